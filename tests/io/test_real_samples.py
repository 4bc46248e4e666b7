"""Importers on the real samples (ScanNet, Scan2CAD, Replica, 3RScan) when they are present.

The data is found by `semloc.eval.datasets.real_data_dir()` (`$SEMLOC_DATA`, else
`../shared/data/real` beside the project); it is third-party data and never part of the
repository.  Expected values are computed here independently of the importers: other readers
(Open3D for PLY, plain json/numpy), scipy rotations, direct counting.
"""

from __future__ import annotations

import json
from collections import Counter

import numpy as np
import pytest
from helpers import real_sample_or_skip
from scipy.spatial.transform import Rotation

from semloc.io.importers.replica import load_replica
from semloc.io.importers.rscan import load_rscan
from semloc.io.importers.scan2cad import load_scan2cad
from semloc.io.importers.scannet import load_scannet
from semloc.maps import MapError

_sample = real_sample_or_skip


def _check_upright_box(obj, points):
    """The box holds all points, is tight along z, and no larger than the axis-aligned box."""
    local = (points - obj.position) @ obj.rotation
    assert np.all(np.abs(local) <= obj.size / 2 + 1e-4)
    assert obj.position[2] == pytest.approx((points[:, 2].min() + points[:, 2].max()) / 2, abs=1e-5)
    assert obj.size[2] == pytest.approx(np.ptp(points[:, 2]), abs=1e-5)
    aabb = np.ptp(points[:, :2], axis=0)
    assert obj.size[0] * obj.size[1] <= aabb[0] * aabb[1] * 1.05 + 1e-6


# ScanNet scene0000_00 --------------------------------------------------------------------------
def test_scannet_scene0000_00():
    import open3d as o3d

    folder = _sample("scannet", "scene0000_00")
    groups = json.loads((folder / "scene0000_00.aggregation.json").read_text())["segGroups"]
    segments = np.array(
        json.loads((folder / "scene0000_00_vh_clean_2.0.010000.segs.json").read_text())[
            "segIndices"
        ]
    )
    vertices = np.asarray(
        o3d.io.read_triangle_mesh(str(folder / "scene0000_00_vh_clean_2.ply")).vertices
    )
    structural = sum(g["label"] in ("wall", "floor", "ceiling") for g in groups)
    assert len(groups) == 55 and structural == 10
    everything = load_scannet(folder, include_structure=True, voxel=0)
    assert len(everything) == 55
    objmap = load_scannet(folder)
    assert len(objmap) == 55 - structural
    assert Counter(objmap.labels) == Counter(
        g["label"] for g in groups if g["label"] not in ("wall", "floor", "ceiling")
    )
    assert Counter(objmap.labels)["cabinet"] == 6 and Counter(objmap.labels)["stool"] == 4
    for group in groups:
        obj = everything.get(str(group["objectId"]))
        points = vertices[np.isin(segments, group["segments"])]
        assert obj.label == group["label"] and len(obj.points) == len(points)
        _check_upright_box(obj, points)
    assert all(len(o.points) < len(everything.get(o.id).points) for o in objmap)


def test_scannet_label_mesh_of_scene0000_00_is_not_nyu40():
    """This sample's `.labels.ply` holds ScanNet category ids (up to 230), not NYU40 ids."""
    folder = _sample("scannet", "scene0000_00")
    with pytest.raises(MapError, match="not NYU40 ids"):
        load_scannet(folder, labels="nyu40")
    mapped = load_scannet(folder, label_map={"trashcan": "otherfurniture", "couch": "sofa"})
    assert Counter(mapped.labels)["otherfurniture"] == 3 and "couch" not in mapped.labels


# Scan2CAD scene0470_00 -------------------------------------------------------------------------
def _trs(trs):
    w, x, y, z = trs["rotation"]
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix() @ np.diag(trs["scale"])
    matrix[:3, 3] = trs["translation"]
    return matrix


def test_scan2cad_scene0470_00():
    folder = _sample("scan2cad", "scene0470_00")
    entry = json.loads((folder / "scan2cad_annotation.json").read_text())[0]
    models = entry["aligned_models"]
    maps = load_scan2cad(folder)
    cad, scan = maps.cad, maps.scan
    assert len(models) == 7 and len(cad) == 7
    ids = Counter(m["id_cad"] for m in models)
    twins = [i for i, m in enumerate(models) if ids[m["id_cad"]] == 2]
    assert len(twins) == 2  # two identical chairs, two objects at different places
    a, b = (cad.get(str(i)) for i in twins)
    assert a.label == b.label == "chair"
    assert np.linalg.norm(a.position - b.position) > 0.5
    scan_from_world = np.linalg.inv(_trs(entry["trs"]))
    for i, model in enumerate(models):
        transform = scan_from_world @ _trs(model["trs"])
        centre = transform @ np.append(model["center"], 1.0)
        obj = cad.get(str(i))
        np.testing.assert_allclose(obj.position, centre[:3], atol=1e-9)
        scale = np.linalg.norm(transform[:3, :3], axis=0)
        np.testing.assert_allclose(obj.size, 2 * np.array(model["bbox"]) * scale, rtol=1e-9)
        label = {"03001627": "chair", "04379243": "table", "02747177": "otherfurniture"}
        assert obj.label == label[model["catid_cad"]]
        # the scan object of the same model: same class, centred near it on the floor plan
        twin = scan.get(str(i))
        assert twin.label == obj.label
        assert np.linalg.norm((twin.position - obj.position)[:2]) < 0.15
    assert scan.up.tolist() == [0, 0, 1]
    assert {"door", "window", "whiteboard"} <= set(scan.labels)
    assert not {"wall", "floor"} & set(scan.labels)


# Replica office4 -------------------------------------------------------------------------------
def test_replica_office4():
    path = _sample("replica", "office4", "info_semantic.json")
    document = json.loads(path.read_text())
    assert len(document["objects"]) == 65
    everything = load_replica(path, include_structure=True, keep_unlabeled=True)
    assert len(everything) == 65
    dropped = {"wall", "floor", "ceiling", "undefined", "non-plane"}
    objmap = load_replica(path)
    assert len(objmap) == sum(o["class_name"] not in dropped for o in document["objects"])
    gravity = np.array(document["gravity_dir"])
    np.testing.assert_allclose(objmap.up, -gravity / np.linalg.norm(gravity))
    for raw in document["objects"]:
        box = raw["oriented_bbox"]
        rotation = Rotation.from_quat(box["orientation"]["rotation"])  # scalar last
        centre = rotation.apply(box["abb"]["center"]) + box["orientation"]["translation"]
        obj = everything.get(str(raw["id"]))
        assert obj.label == raw["class_name"]
        np.testing.assert_allclose(obj.position, centre, atol=1e-6)
        np.testing.assert_allclose(obj.size, box["abb"]["sizes"], atol=1e-9)
    chairs = [o for o in objmap if o.label == "chair"]
    assert len(chairs) == 10
    floor = [o for o in everything if o.label == "floor" and o.size[2] < 0.2][0]
    # chairs stand on the floor: their bottoms are within 10 cm of it
    for chair in chairs:
        bottom = chair.position[2] - np.abs(chair.rotation @ chair.size)[2] / 2
        assert abs(bottom - floor.position[2]) < 0.1


# 3RScan subscans -------------------------------------------------------------------------------
def test_rscan_subscans():
    maps, raw = {}, {}
    for name in ("scene_1", "scene_2"):
        path = _sample("3rscan_subscans", name, "data.npy")
        raw[name] = np.load(path, allow_pickle=False)
        maps[name] = load_rscan(path, include_structure=True, keep_unlabeled=True, voxel=0)
    assert (len(maps["scene_1"]), len(maps["scene_2"])) == (35, 23)
    shared = set(maps["scene_1"].ids) & set(maps["scene_2"].ids)
    assert len(shared) == 18
    nyu40 = ["unlabeled", "wall", "floor", "cabinet", "bed", "chair", "sofa", "table", "door"]
    for name, data in raw.items():
        default = load_rscan(_sample("3rscan_subscans", name))
        nyu_of = {
            int(i): int(np.bincount(data["NYU40"][data["objectId"] == i]).argmax())
            for i in np.unique(data["objectId"])
        }
        structural = {1, 2, 22}
        assert sorted(default.ids, key=int) == sorted(
            (str(i) for i, c in nyu_of.items() if i != 0 and c != 0 and c not in structural),
            key=int,
        )
        for obj in maps[name]:
            mask = data["objectId"] == int(obj.id)
            points = np.column_stack([data["x"][mask], data["y"][mask], data["z"][mask]])
            if nyu_of[int(obj.id)] < len(nyu40):
                assert obj.label == nyu40[nyu_of[int(obj.id)]]
            assert len(obj.points) == mask.sum()
            _check_upright_box(obj, points.astype(float))

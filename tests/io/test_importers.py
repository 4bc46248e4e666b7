"""Importers on small scenes written by the tests (tests/format_fixtures.py): counts, labels,
centres and boxes against the generating values; bad files give a MapError naming the file."""

from __future__ import annotations

import json

import numpy as np
import pytest
from format_fixtures import (
    REPLICA_OBJECTS,
    RSCAN_OBJECTS,
    SCAN2CAD_MODELS,
    SCAN2CAD_SCAN_TRS,
    SCANNET_BOXES,
    write_replica,
    write_rscan,
    write_scan2cad,
    write_scannet,
)
from scipy.spatial.transform import Rotation

from semloc.io.importers.replica import load_replica
from semloc.io.importers.rscan import load_rscan
from semloc.io.importers.scan2cad import load_scan2cad
from semloc.io.importers.scannet import load_scannet
from semloc.maps import MapError


def _check_box(obj, centre, size, yaw):
    np.testing.assert_allclose(obj.position, centre, atol=1e-5)
    np.testing.assert_allclose(obj.size, size, atol=1e-5)
    axis = np.array([np.cos(yaw), np.sin(yaw), 0.0])
    assert abs(obj.rotation[:, 0] @ axis) == pytest.approx(1.0, abs=1e-6)
    np.testing.assert_allclose(obj.rotation[:, 2], [0, 0, 1], atol=1e-9)


# ScanNet ---------------------------------------------------------------------------------------
def test_scannet_objects_boxes_and_points(tmp_path):
    write_scannet(tmp_path)
    objmap = load_scannet(tmp_path, voxel=0)
    expected = [b for b in SCANNET_BOXES if b[1] not in ("wall", "floor")]
    assert list(objmap.ids) == [str(b[0]) for b in expected]
    assert list(objmap.labels) == [b[1] for b in expected]
    np.testing.assert_allclose(objmap.up, [0, 0, 1])
    for obj, (_, _, _, centre, size, yaw) in zip(objmap, expected, strict=True):
        _check_box(obj, centre, size, yaw)
        assert len(obj.points) == 26


def test_scannet_structure_nyu40_and_label_map(tmp_path):
    write_scannet(tmp_path)
    everything = load_scannet(tmp_path / "scene0001_00.aggregation.json", include_structure=True)
    assert len(everything) == len(SCANNET_BOXES)
    nyu = load_scannet(tmp_path, labels="nyu40")
    assert list(nyu.labels) == ["chair", "table", "chair"]
    assert nyu.get("2").extra["raw_label"] == "office chair"
    mapped = load_scannet(tmp_path, label_map={"office chair": "chair"})
    assert list(mapped.labels) == ["chair", "table", "chair"]


def test_scannet_voxel_downsampling_reduces_points(tmp_path):
    write_scannet(tmp_path)
    coarse = load_scannet(tmp_path, voxel=10.0)
    assert all(len(o.points) == 1 for o in coarse)


def test_scannet_mismatched_vertex_count(tmp_path):
    write_scannet(tmp_path)
    segs_path = tmp_path / "scene0001_00_vh_clean_2.0.010000.segs.json"
    segs = json.loads(segs_path.read_text())
    segs["segIndices"] = segs["segIndices"][:-3]
    segs_path.write_text(json.dumps(segs))
    with pytest.raises(MapError, match=r"segs\.json: \d+ segment indices but the mesh .* has"):
        load_scannet(tmp_path)


def test_scannet_truncated_mesh(tmp_path):
    write_scannet(tmp_path)
    mesh = tmp_path / "scene0001_00_vh_clean_2.ply"
    mesh.write_bytes(mesh.read_bytes()[:300])
    with pytest.raises(MapError, match=r"_vh_clean_2\.ply: truncated"):
        load_scannet(tmp_path)


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda a: a.pop("segGroups"), "missing key 'segGroups'"),
        (lambda a: a["segGroups"][1].pop("segments"), r"segGroups\[1\]: missing key 'segments'"),
        (lambda a: a["segGroups"][2].update(objectId=0), "objectId 0 is not a new integer"),
        (lambda a: a["segGroups"][0].update(segments=[999]), "objectId 0 has no vertex"),
    ],
)
def test_scannet_bad_aggregation(tmp_path, edit, message):
    write_scannet(tmp_path)
    path = tmp_path / "scene0001_00.aggregation.json"
    document = json.loads(path.read_text())
    edit(document)
    path.write_text(json.dumps(document))
    with pytest.raises(MapError, match=message) as info:
        load_scannet(tmp_path)
    assert "aggregation.json" in str(info.value)


def test_scannet_label_mesh_with_other_vertex_count(tmp_path):
    from semloc.io.ply import read_ply, write_ply

    write_scannet(tmp_path)
    path = tmp_path / "scene0001_00_vh_clean_2.labels.ply"
    write_ply(path, read_ply(path).vertices[:-1])
    with pytest.raises(MapError, match=r"labels\.ply: \d+ vertices but the mesh has \d+"):
        load_scannet(tmp_path, labels="nyu40")


def test_scannet_refuses_label_mesh_that_is_not_nyu40(tmp_path):
    from semloc.io.ply import read_ply, write_ply

    write_scannet(tmp_path)
    path = tmp_path / "scene0001_00_vh_clean_2.labels.ply"
    mesh = read_ply(path)
    vertices = mesh.vertices.copy()
    vertices["label"] = np.where(vertices["label"] == 5, 2, 5)  # chair<->floor ids swapped
    write_ply(path, vertices, mesh.faces)
    with pytest.raises(MapError, match="labels.ply: per-vertex labels disagree"):
        load_scannet(tmp_path, labels="nyu40")


# Scan2CAD --------------------------------------------------------------------------------------
def _scan_from_world(t, q_wxyz, s):
    model = np.eye(4)
    model[:3, :3] = Rotation.from_quat([*q_wxyz[1:], q_wxyz[0]]).as_matrix() @ np.diag(s)
    model[:3, 3] = t
    return model


def test_scan2cad_cad_map_in_scan_frame(tmp_path):
    path = write_scan2cad(tmp_path)
    maps = load_scan2cad(path, voxel=0, points_per_model=300)
    scan = SCAN2CAD_SCAN_TRS
    inv_scan = np.linalg.inv(_scan_from_world(scan["translation"], scan["rotation"], [1, 1, 1]))
    assert list(maps.cad.ids) == ["0", "1", "2"]
    assert list(maps.cad.labels) == ["chair", "chair", "table"]
    np.testing.assert_allclose(maps.cad.up, [0, 0, 1])
    for obj, (_, _, t, _yaw, s) in zip(maps.cad, SCAN2CAD_MODELS, strict=True):
        expected = inv_scan @ np.append(t, 1.0)
        np.testing.assert_allclose(obj.position, expected[:3], atol=1e-9)
        np.testing.assert_allclose(obj.size, s, atol=1e-9)
        # the model's up (y) is the scan's +z
        np.testing.assert_allclose(obj.rotation[:, 1], [0, 0, 1], atol=1e-9)
        local = (obj.points - obj.position) @ obj.rotation
        assert len(obj.points) == 300
        assert np.all(np.abs(local) <= np.asarray(s) / 2 + 1e-9)
        on_face = np.isclose(np.abs(local) / (np.asarray(s) / 2), 1.0, atol=1e-9).any(axis=1)
        assert on_face.all()
    assert maps.cad[0].extra["catid_cad"] == "03001627"
    shapenet = load_scan2cad(path, labels="shapenet").cad
    assert list(shapenet.labels) == ["chair", "chair", "table"]


def test_scan2cad_scan_map_from_labelled_mesh(tmp_path):
    path = write_scan2cad(tmp_path)
    maps = load_scan2cad(path, voxel=0)
    scan = maps.scan
    assert list(scan.ids) == ["0", "1", "2", "3"]
    assert list(scan.labels) == ["chair", "chair", "table", "door"]
    for i in range(3):
        np.testing.assert_allclose(scan[i].position, maps.cad[i].position, atol=1e-5)
        np.testing.assert_allclose(
            sorted(scan[i].size), sorted(np.array(SCAN2CAD_MODELS[i][4]) * 0.95), atol=1e-5
        )
    np.testing.assert_allclose(scan[3].position, [4.0, 0.0, 1.0], atol=1e-5)
    with_walls = load_scan2cad(path, include_structure=True).scan
    assert list(with_walls.labels).count("wall") == 1


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda e: e.pop("aligned_models"), "missing key 'aligned_models'"),
        (lambda e: e["aligned_models"][1].pop("trs"), r"aligned_models\[1\]: missing key 'trs'"),
        (lambda e: e["trs"].update(rotation=[0, 0, 0, 0]), "trs: quaternion has zero"),
        (lambda e: e.update(n_aligned_models=5), "n_aligned_models is 5 but 3 models"),
        (lambda e: e["aligned_models"][0].update(id_cad="gone"), "gone/model_normalized.obj: CAD"),
    ],
)
def test_scan2cad_bad_annotation(tmp_path, edit, message):
    path = write_scan2cad(tmp_path)
    document = json.loads(path.read_text())
    edit(document[0])
    path.write_text(json.dumps(document))
    with pytest.raises(MapError, match=message):
        load_scan2cad(path)


def test_scan2cad_scan_dir_elsewhere_and_missing(tmp_path):
    path = write_scan2cad(tmp_path)
    elsewhere = tmp_path / "scans"
    elsewhere.mkdir()
    mesh = path.parent / "scene0002_00_vh_clean_2.labels.ply"
    mesh.rename(elsewhere / mesh.name)
    assert load_scan2cad(path).scan is None
    assert len(load_scan2cad(path, scan_dir=elsewhere).scan) == 4


def test_scan2cad_bad_obj(tmp_path):
    path = write_scan2cad(tmp_path)
    obj = tmp_path / "shapenet" / "04379243" / "tablecube" / "model_normalized.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nf 1 2 9\n")
    with pytest.raises(MapError, match="model_normalized.obj: .*vertex that does not exist"):
        load_scan2cad(path)


# Replica ---------------------------------------------------------------------------------------
def test_replica_boxes_points_and_up(tmp_path):
    path = write_replica(tmp_path)
    objmap = load_replica(path)
    assert list(objmap.ids) == ["3", "7"]
    assert list(objmap.labels) == ["chair", "table"]
    np.testing.assert_allclose(objmap.up, [0, 0, 1])
    for obj, (_, _, centre, sizes, yaw, t) in zip(objmap, REPLICA_OBJECTS, strict=False):
        rotation = Rotation.from_quat([0, 0, np.sin(yaw / 2), np.cos(yaw / 2)]).as_matrix()
        np.testing.assert_allclose(obj.position, rotation @ centre + np.array(t), atol=1e-9)
        np.testing.assert_allclose(obj.size, sizes)
        np.testing.assert_allclose(obj.rotation, rotation, atol=1e-9)
        local = (obj.points - obj.position) @ obj.rotation
        reach = np.max(np.abs(local) / (np.asarray(sizes) / 2), axis=1)
        np.testing.assert_allclose(reach, 1.0, atol=1e-9)
        assert 20 <= len(obj.points) <= 1000
    assert len(load_replica(path, include_structure=True, keep_unlabeled=True)) == 4


def test_replica_up_is_minus_gravity(tmp_path):
    objmap = load_replica(write_replica(tmp_path, gravity=(0.0, -2.0, 0.0)))
    np.testing.assert_allclose(objmap.up, [0, 1, 0])


@pytest.mark.parametrize(
    ("edit", "message"),
    [
        (lambda d: d.pop("objects"), "missing key 'objects'"),
        (lambda d: d["objects"][1].pop("oriented_bbox"), r"objects\[1\]: missing key 'orient"),
        (lambda d: d["objects"][0]["oriented_bbox"]["abb"].pop("sizes"), "lacks 'sizes'"),
        (lambda d: d.update(gravity_dir=[0, 0]), r"'gravity_dir' must have shape \(3,\)"),
        (lambda d: d.update(gravity_dir=[0, 0, 0]), "'gravity_dir' must be a non-zero vector"),
        (lambda d: d.update(gravity_dir=[1e308, 1e308, 0]), "'gravity_dir' .* too large"),
    ],
)
def test_replica_bad_file(tmp_path, edit, message):
    path = write_replica(tmp_path)
    document = json.loads(path.read_text())
    edit(document)
    path.write_text(json.dumps(document))
    with pytest.raises(MapError, match=message) as info:
        load_replica(path)
    assert "info_semantic.json" in str(info.value)


# 3RScan ----------------------------------------------------------------------------------------
def test_rscan_objects(tmp_path):
    write_rscan(tmp_path)
    objmap = load_rscan(tmp_path, voxel=0)
    kept = [o for o in RSCAN_OBJECTS if o[0] != 0 and o[1] != 1]
    assert list(objmap.ids) == [str(o[0]) for o in kept]
    assert list(objmap.labels) == ["chair", "table", "cabinet"]
    for obj, (_, _, _, centre, size) in zip(objmap, kept, strict=True):
        np.testing.assert_allclose(obj.position, centre, atol=1e-5)
        np.testing.assert_allclose(obj.size, size, atol=1e-5)
        assert len(obj.points) == 26
    everything = load_rscan(tmp_path / "data.npy", include_structure=True, keep_unlabeled=True)
    assert len(everything) == len(RSCAN_OBJECTS)
    assert list(load_rscan(tmp_path, labels="rio27").labels) == ["chair", "table", "cabinet"]


def test_rscan_missing_field_and_bad_ids(tmp_path):
    write_rscan(tmp_path, drop_field="objectId")
    with pytest.raises(MapError, match=r"data\.npy: missing fields \['objectId'\]"):
        load_rscan(tmp_path)
    path = write_rscan(tmp_path)
    data = np.load(path)
    data["NYU40"][data["objectId"] == 4] = 77
    np.save(path, data)
    with pytest.raises(MapError, match="objectId 4: unknown NYU40 class id 77"):
        load_rscan(path)
    path.write_bytes(b"\x93NUMPY garbage")
    with pytest.raises(MapError, match="not a readable .npy"):
        load_rscan(path)

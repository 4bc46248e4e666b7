"""Real scans as simulator worlds (semloc.sim.realscan): instances, rays, walks, fused objects.

A tiny ScanNet-format scene written here checks the per-face instances and rays exactly; the
real samples (ScanNet scene0000_00, Scan2CAD scene0470_00) are used when present and the tests
skip with a reason when they are not.  Ray checks read the labels independently of the code
under test (plain json for the aggregation, nearest mesh vertex of the hit point).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial import cKDTree

from semloc.eval.datasets import real_sample
from semloc.io.ply import read_ply, write_ply
from semloc.maps import MapError
from semloc.sim.noise import DetectionNoise
from semloc.sim.realscan import free_space, load_real_scan, simulate_walk, walk_path
from semloc.sim.sensor import Intrinsics, look_at
from semloc.sim.shapes import Mesh, box

K = Intrinsics.scannet(64, 48)
CENTRE = (24, 32)  # row, column of the optical centre of K


def _sample(*parts):
    path = real_sample(*parts)
    if path is None:
        pytest.skip(f"real data sample {'/'.join(parts)} not found (set SEMLOC_DATA)")
    return path


def _write_scene(folder, name="scene0009_00", colours=False):
    """A 6 x 4 m room: floor, two walls, a chair box and a table box, one segment each (with
    `colours`: random vertex colours)."""
    parts = [
        ("floor", box((0, 0, -0.005), (6, 4, 0.01))),
        ("wall", box((0, 2.05, 1.3), (6, 0.1, 2.6))),
        ("chair", box((2.0, 0.0, 0.45), (0.5, 0.5, 0.9))),
        ("table", box((-1.5, 1.0, 0.4), (1.2, 0.8, 0.8))),
        ("wall", box((3.05, 0, 1.3), (0.1, 4, 2.6))),
    ]
    mesh = Mesh.concat([m for _, m in parts])
    segments = np.repeat(np.arange(len(parts)), 8)
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    fields += [(c, "u1") for c in ("red", "green", "blue")] if colours else []
    vertices = np.zeros(len(mesh.vertices), dtype=fields)
    for i, c in enumerate("xyz"):
        vertices[c] = mesh.vertices[:, i]
    rng = np.random.default_rng(0)
    for c in ("red", "green", "blue") if colours else ():
        vertices[c] = rng.integers(20, 235, len(vertices))
    write_ply(folder / f"{name}_vh_clean_2.ply", vertices, mesh.triangles)
    (folder / f"{name}_vh_clean_2.0.010000.segs.json").write_text(
        json.dumps({"segIndices": segments.tolist()})
    )
    groups = [{"objectId": 10 + i, "label": label, "segments": [i]}
              for i, (label, _) in enumerate(parts)]  # fmt: skip
    (folder / f"{name}.aggregation.json").write_text(json.dumps({"segGroups": groups}))


def test_written_scene_faces_and_rays(tmp_path):
    _write_scene(tmp_path)
    scan = load_real_scan(tmp_path)
    assert scan.source == "scannet" and scan.name == "scene0009_00"
    assert [(o.id, o.label) for o in scan.objects] == [("12", "chair"), ("13", "table")]
    # 12 triangles per box, in the order written: floor, wall, chair, table, wall
    expected = np.repeat([-1, -1, 0, 1, -1], 12)
    assert np.array_equal(scan.face_instance, expected)
    sensor = scan.sensor(K)
    frame = sensor.render(look_at(np.array([0.0, 0.0, 0.45]), np.array([2.0, 0.0, 0.45])))
    assert frame.instance[CENTRE] == 0  # the chair
    assert frame.depth[CENTRE] == pytest.approx(1.75, abs=1e-4)  # its near face at x = 1.75
    frame = sensor.render(look_at(np.array([0.0, -1.0, 1.2]), np.array([-1.5, 1.0, 0.4])))
    assert frame.instance[CENTRE] == 1  # the table
    frame = sensor.render(look_at(np.array([0.0, -1.0, 1.4]), np.array([0.0, -1.0, 0.0])))
    assert frame.instance[CENTRE] == -1  # the floor is background
    assert frame.depth[CENTRE] == pytest.approx(1.4, abs=1e-4)


def test_written_scene_walk_stays_in_free_space(tmp_path):
    _write_scene(tmp_path)
    scan = load_real_scan(tmp_path)
    free, origin = free_space(scan)
    poses = walk_path(scan, n_keyframes=12, seed=1)
    cells = np.floor((poses[:, :2, 3] - origin) / 0.1).astype(int)
    assert free[tuple(cells.T)].all()
    assert np.allclose(poses[:, 2, 3], 1.4, atol=0.15)  # eye height above the floor (z = 0)
    # never inside the furniture, and a clearance around it
    for lo, hi in (((1.75, -0.25), (2.25, 0.25)), ((-2.1, 0.6), (-0.9, 1.4))):
        gap = np.maximum(np.maximum(np.subtract(lo, poses[:, :2, 3]), 0),
                         np.maximum(poses[:, :2, 3] - hi, 0))  # fmt: skip
        assert np.linalg.norm(gap, axis=1).min() >= 0.2  # clearance 0.3 m on a 0.1 m grid


def test_folder_errors(tmp_path):
    with pytest.raises(MapError, match="no such scene folder"):
        load_real_scan(tmp_path / "missing")
    with pytest.raises(MapError, match="neither a ScanNet scene"):
        load_real_scan(tmp_path)


def _vertex_instances(folder, name):
    """objectId of every mesh vertex, straight from the aggregation and segments (or -1)."""
    segs = json.loads((folder / f"{name}_vh_clean_2.0.010000.segs.json").read_text())
    groups = json.loads((folder / f"{name}.aggregation.json").read_text())["segGroups"]
    by_segment = {s: g["objectId"] for g in groups for s in g["segments"]}
    return np.array([by_segment.get(s, -1) for s in segs["segIndices"]])


def _hit_owner(frame, tree, owner):
    """Owner of the mesh vertex nearest to each pixel's hit point (world frame)."""
    from semloc.sim.sensor import backproject

    points = backproject(frame.depth, K)
    T = frame.T_world_camera
    _, nearest = tree.query(points @ T[:3, :3].T + T[:3, 3])
    return owner[nearest]


def test_scannet_rays_agree_with_the_aggregation():
    folder = _sample("scannet", "scene0000_00")
    scan = load_real_scan(folder)
    owner = _vertex_instances(folder, "scene0000_00")
    ply = read_ply(folder / "scene0000_00_vh_clean_2.ply").vertices
    tree = cKDTree(np.column_stack([ply[c] for c in "xyz"]))
    sensor = scan.sensor(K)
    eye = np.array([3.5, 4.0, 1.4])
    # hand-checked: from the middle of the room, these objects' centres are in plain view
    for object_id, label in (("33", "refrigerator"), ("34", "table"), ("37", "bed"),
                             ("54", "door")):  # fmt: skip
        target = scan.global_maps["reconstruction"].get(object_id).position
        frame = sensor.render(look_at(eye, target))
        hit = scan.objects[frame.instance[CENTRE]]
        assert (hit.id, hit.label) == (object_id, label)
        truth = _hit_owner(frame, tree, owner)
        ids = np.array([int(scan.objects[i].id) if i >= 0 else -1
                        for i in frame.instance[frame.depth > 0]])  # fmt: skip
        # instance pixels agree with the labels of the vertices they hit (walls etc. excluded)
        labelled = ids >= 0
        assert np.mean(ids[labelled] == truth[labelled]) > 0.95


def test_scan2cad_rays_see_the_annotated_objects():
    folder = _sample("scan2cad", "scene0470_00")
    scan = load_real_scan(folder)
    assert set(scan.global_maps) == {"reconstruction", "cad"}
    sensor = scan.sensor(K)
    scan_map = scan.global_maps["reconstruction"]
    eye = np.array([2.0, 1.7, 1.4])
    # hand-checked: trash bin, chair, table, whiteboard; the chair by the wall has the bag
    # standing in front of it, which the centre ray hits first
    for object_id, seen in (("0", "0"), ("2", "2"), ("5", "5"), ("9", "9"), ("1", "10")):
        frame = sensor.render(look_at(eye, scan_map.get(object_id).position))
        assert scan.objects[frame.instance[CENTRE]].id == seen
    assert scan_map.get("10").label == "bag"


@pytest.mark.parametrize(("parts", "kind"), [(("scannet", "scene0000_00"), "reconstruction"),
                                             (("scan2cad", "scene0470_00"), "cad")])  # fmt: skip
def test_fused_objects_match_the_scan_instances(parts, kind):
    scan = load_real_scan(_sample(*parts))
    seq = simulate_walk(scan, n_keyframes=30, seed=0, resolution=(120, 90),
                        noise=DetectionNoise.perfect())  # fmt: skip
    gmap = seq.global_maps["reconstruction"]
    matched = [(lid, g) for lid, g in seq.local_truth.items() if g is not None]
    assert len(matched) >= 0.8 * len(seq.local_map) and len(matched) >= 5
    T = seq.T_global_local
    right = 0
    for lid, g in matched:
        local, truth = seq.local_map.get(lid), gmap.get(g)
        centre = T[:3, :3] @ local.position + T[:3, 3]
        # a partial view moves the centre of the points by at most half the object's extent
        assert np.linalg.norm(centre - truth.position) <= 0.5 * np.linalg.norm(truth.size) + 0.05
        right += local.label == truth.label
    assert right >= 0.9 * len(matched)
    assert len(seq.correspondences(kind)) >= 3


def test_scans_keep_vertex_colours_and_render_them(tmp_path):
    """The written scene's mesh has vertex colours: the colour sensor interpolates them over
    the triangle hit (unshaded), with the depth sensor's depth."""
    _write_scene(tmp_path, colours=True)
    scan = load_real_scan(tmp_path)
    assert scan.colours is not None and scan.colours.shape == (len(scan.mesh.vertices), 3)
    K = Intrinsics.scannet(64, 48)
    T = walk_path(scan, 40, 0)[0]
    frame = scan.colour_sensor(K).render(T)
    depth = scan.sensor(K).render(T).depth
    assert np.allclose(frame.depth, depth)
    hit = frame.depth > 0
    lo, hi = scan.colours.min(axis=0) * 255 - 1, scan.colours.max(axis=0) * 255 + 1
    assert np.all((frame.rgb[hit] >= lo) & (frame.rgb[hit] <= hi))
    assert np.all(frame.rgb[~hit] == 0)
    assert frame.rgb[hit].std() > 5  # interpolated, not one colour
    uncoloured = tmp_path / "plain"
    uncoloured.mkdir()
    _write_scene(uncoloured)
    with pytest.raises(MapError, match="no vertex colours"):
        load_real_scan(uncoloured).colour_sensor(K)

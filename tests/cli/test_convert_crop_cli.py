"""`semloc convert` and `semloc crop`: outputs, ground truth, and one-line errors (exit 2)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from format_fixtures import write_replica, write_rscan, write_scan2cad, write_scannet
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc.cli import main
from semloc.io import load_map
from semloc.maps import MapError, ObjectMap, SemanticObject
from semloc.sim.crop import crop_with_truth, visible_points


def _one_error_line(capsys, *fragments):
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("semloc: error: "), err
    assert "Traceback" not in err
    for fragment in fragments:
        assert fragment in err, err


def test_convert_each_kind(tmp_path):
    write_scannet(tmp_path / "sn")
    write_rscan(tmp_path / "rs")
    replica = write_replica(tmp_path / "rep")
    annotation = write_scan2cad(tmp_path / "s2c")
    cases = [
        ("scannet", tmp_path / "sn", 3),
        ("3rscan", tmp_path / "rs" / "data.npy", 3),
        ("replica", replica, 2),
        ("scan2cad", annotation, 3),
    ]
    for kind, source, count in cases:
        out = tmp_path / f"{kind}.json"
        assert main(["convert", kind, str(source), "-o", str(out)]) == 0
        assert len(load_map(out)) == count
    assert len(load_map(tmp_path / "scan2cad.scan.json")) == 4
    out = tmp_path / "all.json"
    assert (
        main(
            [
                "convert",
                "scannet",
                str(tmp_path / "sn"),
                "-o",
                str(out),
                "--include-structure",
                "--labels",
                "nyu40",
            ]
        )
        == 0
    )
    assert sorted(set(load_map(out).labels)) == ["chair", "floor", "table", "wall"]


def test_convert_label_map_file(tmp_path):
    write_scannet(tmp_path / "sn")
    tsv = tmp_path / "labels.tsv"
    tsv.write_text("id\traw_category\tnyu40class\n1\toffice chair\tchair\n2\ttable\ttable\n")
    out = tmp_path / "m.json"
    assert (
        main(["convert", "scannet", str(tmp_path / "sn"), "-o", str(out), "--label-map", str(tsv)])
        == 0
    )
    assert list(load_map(out).labels) == ["chair", "table", "chair"]


def test_convert_truncated_ply_exits_2(tmp_path, capsys):
    write_scannet(tmp_path)
    mesh = tmp_path / "scene0001_00_vh_clean_2.ply"
    mesh.write_bytes(mesh.read_bytes()[:-50])
    assert main(["convert", "scannet", str(tmp_path), "-o", str(tmp_path / "o.json")]) == 2
    _one_error_line(capsys, "scene0001_00_vh_clean_2.ply", "truncated")
    assert not (tmp_path / "o.json").exists()


def test_convert_missing_key_exits_2(tmp_path, capsys):
    path = write_replica(tmp_path)
    document = json.loads(path.read_text())
    del document["objects"][0]["class_name"]
    path.write_text(json.dumps(document))
    assert main(["convert", "replica", str(path), "-o", str(tmp_path / "o.json")]) == 2
    _one_error_line(capsys, "info_semantic.json", "missing key 'class_name'")


def test_convert_mismatched_counts_exits_2(tmp_path, capsys):
    write_scannet(tmp_path)
    segs = tmp_path / "scene0001_00_vh_clean_2.0.010000.segs.json"
    document = json.loads(segs.read_text())
    document["segIndices"].append(100)
    segs.write_text(json.dumps(document))
    assert main(["convert", "scannet", str(tmp_path), "-o", str(tmp_path / "o.json")]) == 2
    _one_error_line(capsys, "segs.json", "segment indices but the mesh")


@pytest.mark.parametrize(
    ("args", "fragment"),
    [
        (["convert", "3rscan", "{d}", "--shapenet", "x"], "--shapenet does not apply to 3rscan"),
        (["convert", "3rscan", "{d}", "--labels", "klingon"], "labels must be one of"),
        (["convert", "3rscan", "{d}", "--voxel", "-1"], "--voxel"),
        (["convert", "blender", "{d}"], "blender"),
    ],
)
def test_convert_bad_usage_exits_2(tmp_path, capsys, args, fragment):
    write_rscan(tmp_path)
    argv = [a.format(d=tmp_path) for a in args] + ["-o", str(tmp_path / "o.json")]
    assert main(argv) == 2
    _one_error_line(capsys, fragment)


# crop ------------------------------------------------------------------------------------------
def _grid_map() -> ObjectMap:
    rng = np.random.default_rng(1)
    objects = []
    for i in range(12):
        centre = np.array([i % 4 * 2.0, i // 4 * 2.0, 0.5])
        objects.append(
            SemanticObject(
                id=f"g{i}",
                label=["chair", "table"][i % 2],
                position=centre,
                points=centre + rng.uniform(-0.3, 0.3, (40, 3)),
            )
        )
    return ObjectMap(objects, up=[0, 0, 1], name="grid")


def test_crop_cli_writes_local_map_and_truth(tmp_path):
    from semloc.io import save_map

    save_map(_grid_map(), tmp_path / "g.json")
    out = tmp_path / "local.json"
    argv = [
        "crop",
        str(tmp_path / "g.json"),
        "--center",
        "2",
        "2",
        "0.5",
        "--radius",
        "2.1",
        "-o",
        str(out),
        "--seed",
        "3",
    ]
    assert main(argv) == 0
    local = load_map(out)
    truth = json.loads((tmp_path / "local.gt.json").read_text())
    T = np.array(truth["T_global_local"])
    assert T.shape == (4, 4) and not np.allclose(T, np.eye(4))
    pairs = {p["local"]: p["global"] for p in truth["pairs"]}
    assert sorted(pairs.values()) == ["g1", "g4", "g5", "g6", "g9"]
    global_map = _grid_map()
    for obj in local:
        expected = global_map.get(pairs[obj.id]).position
        np.testing.assert_allclose(T[:3, :3] @ obj.position + T[:3, 3], expected, atol=1e-5)
    np.testing.assert_allclose(T[:3, :3] @ local.up, [0, 0, 1], atol=1e-6)
    # an explicit transform file, and 'none'
    pose = np.eye(4)
    pose[:3, 3] = [1, 2, 3]
    (tmp_path / "pose.json").write_text(json.dumps({"T_global_local": pose.tolist()}))
    assert main([*argv[:-2], "--transform", str(tmp_path / "pose.json")]) == 0
    np.testing.assert_allclose(load_map(out).get("l0").position, [1, 0, -2.5], atol=1e-6)
    assert main([*argv[:-2], "--transform", "none"]) == 0
    np.testing.assert_allclose(load_map(out).get("l0").position, [2, 2, 0.5], atol=1e-6)


@pytest.mark.parametrize(
    ("extra", "fragment"),
    [
        (["--radius", "0.1", "--center", "50", "50", "0"], "no object of"),
        (["--radius", "-1", "--center", "0", "0", "0"], "radius must be a positive"),
        (["--radius", "3", "--center", "0", "0", "0", "--transform", "{bad}"], "4x4 matrix"),
    ],
)
def test_crop_cli_errors(tmp_path, capsys, extra, fragment):
    from semloc.io import save_map

    save_map(_grid_map(), tmp_path / "g.json")
    (tmp_path / "bad.json").write_text("[[1, 0], [0, 1]]")
    extra = [e.format(bad=tmp_path / "bad.json") for e in extra]
    assert main(["crop", str(tmp_path / "g.json"), *extra, "-o", str(tmp_path / "l.json")]) == 2
    _one_error_line(capsys, fragment)


def test_crop_rejects_non_rigid_transform():
    with pytest.raises(MapError, match="not a proper rotation"):
        crop_with_truth(_grid_map(), [0, 0, 0], 3.0, transform=np.diag([2.0, 1, 1, 1]))


@settings(max_examples=40)
@given(
    center=st.tuples(*[st.floats(-1, 7, allow_nan=False)] * 2, st.floats(0, 2)),
    radius=st.floats(0.5, 6),
    seed=st.integers(0, 2**31),
)
def test_crop_geometry(center, radius, seed):
    global_map = _grid_map()
    center = np.array(center)
    local, truth = crop_with_truth(global_map, center, radius, "random", seed)
    T = truth.T_global_local
    np.testing.assert_allclose(T[:3, :3] @ T[:3, :3].T, np.eye(3), atol=1e-9)
    np.testing.assert_allclose(T[:3, :3] @ [0, 0, 1], [0, 0, 1], atol=1e-9)  # yaw about up
    within = [o.id for o in global_map if np.linalg.norm(o.position - center) <= radius]
    assert sorted(g for g, _ in truth.pairs) == sorted(within)
    distances = []
    for (gid, lid), obj in zip(truth.pairs, local, strict=True):
        source = global_map.get(gid)
        assert obj.id == lid and obj.label == source.label
        back = obj.transformed(T)
        np.testing.assert_allclose(back.position, source.position, atol=1e-9)
        facing = (back.points - source.position) @ (center - source.position)
        assert np.all(facing >= -1e-9) or len(back.points) == 3
        assert len(back.points) <= len(source.points)
        distances.append(np.linalg.norm(source.position - center))
    assert np.all(np.diff(distances) >= -1e-9)
    assert list(local.seen) == list(range(len(local)))


def test_visible_points_keeps_the_facing_half():
    obj = SemanticObject(
        id="a",
        label="box",
        position=[0, 0, 0],
        points=[[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0.5, 0.5, 0]],
    )
    kept = visible_points(obj, np.array([5.0, 0, 0]), min_points=1)
    np.testing.assert_allclose(kept, [[1, 0, 0], [0, 1, 0], [0.5, 0.5, 0]])


def test_writers_store_descriptors_and_crop_drops_stale_ones(tmp_path):
    from semloc import descriptors
    from semloc.io import save_map

    write_rscan(tmp_path / "rs")
    out = tmp_path / "rs.json"
    assert main(["convert", "3rscan", str(tmp_path / "rs"), "-o", str(out),
                 "--descriptor", "geometric"]) == 0  # fmt: skip
    from semloc.io import importers

    imported = importers.convert("3rscan", tmp_path / "rs")[0]  # points before rounding to file
    for obj, written in zip(imported, load_map(out)):
        np.testing.assert_allclose(written.descriptor, descriptors.compute(obj.points), atol=1e-6)
    # a map with whole-object descriptors: a crop keeps only visible points, so not those
    save_map(descriptors.with_descriptors(_grid_map()), tmp_path / "g.json")
    argv = ["crop", str(tmp_path / "g.json"), "--center", "2", "2", "0.5", "--radius", "2.1",
            "-o", str(tmp_path / "l.json")]  # fmt: skip
    assert main(argv) == 0
    assert all(o.descriptor is None for o in load_map(tmp_path / "l.json"))
    assert main([*argv, "--descriptor", "voxnet"]) == 0
    local = load_map(tmp_path / "l.json")
    assert all(o.descriptor is not None and o.descriptor.shape == (64,) for o in local)
    assert np.all(np.isfinite(local.get("l0").descriptor))

"""`semloc update-map`: moved objects moved, new ones added, missing ones flagged; all or none."""

from __future__ import annotations

import json

import numpy as np
from test_changes_fixtures import T, cube, room, seen_from_t  # noqa: F401

import semloc
from semloc.cli import main
from semloc.maps import ObjectMap, SemanticObject
from semloc.transforms import yaw_pose


def write_scene(folder):
    g = room()
    objects = list(g)
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))  # lamp moved 1.5 m
    objects[5] = SemanticObject("g9", "bed", points=cube([4.5, 1.0, 0.4], seed=9))  # new
    # the plant (g5) is gone; a bin stands right beside its place
    objects.append(SemanticObject("g11", "bin", points=cube([4.0, 3.8, 0.6], seed=11)))
    semloc.save_map(g, folder / "global.json")
    semloc.save_map(ObjectMap(seen_from_t(objects), up=[0, 0, 1]), folder / "local.json")
    return g


def test_update_map_applies_every_change(tmp_path, capsys):
    g = write_scene(tmp_path)
    out = tmp_path / "updated.json"
    assert main(["update-map", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                 "-o", str(out)]) == 0  # fmt: skip
    text = capsys.readouterr().out
    assert "changes, moved: g4" in text and "changes, new: l9, l11" in text
    updated = semloc.load_map(out)
    lamp = updated.get("g4")
    np.testing.assert_allclose(lamp.position, g.get("g4").position + [1.2, -0.9, 0.0], atol=0.05)
    assert lamp.extra["moved_m"] > 1.4
    assert updated.get("l9").label == "bed" and updated.get("l9").extra["new"] is True
    assert updated.get("g5").extra.get("missing") is True  # the plant beside the seen bin
    assert len(updated) == len(g) + 2  # the bed and the second bin; nothing deleted


def test_the_updated_map_localizes_the_same_view_with_every_object_matched(tmp_path):
    """Round trip: after `update-map` the moved lamp stands where it was seen and the bed and
    the bin are in the map, so the view is explained without a change (the plant stays flagged
    missing: it is still gone, and flagged objects are kept)."""
    g = write_scene(tmp_path)
    updated, result = tmp_path / "updated.json", tmp_path / "result.json"
    assert main(["update-map", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                 "-o", str(updated)]) == 0  # fmt: skip
    assert main(["localize", str(updated), str(tmp_path / "local.json"), "--format", "json",
                 "-o", str(result)]) == 0  # fmt: skip
    answer = json.loads(result.read_text())
    assert answer["status"] == "localized"
    np.testing.assert_allclose(answer["pose"], T, atol=1e-3)
    assert answer["changes"]["moved"] == [] and answer["changes"]["new"] == []
    pairs = {p["local"]: p["global"] for p in answer["hypotheses"][0]["pairs"]}
    local = semloc.load_map(tmp_path / "local.json")
    assert sorted(pairs) == sorted(local.ids.tolist())  # every local object matched
    assert pairs["l4"] == "g4" and pairs["l9"] == "l9" and pairs["l11"] == "l11"
    assert len(semloc.load_map(updated)) == len(g) + 2


def test_update_map_from_a_saved_result_gives_the_same_map(tmp_path):
    write_scene(tmp_path)
    result = tmp_path / "result.json"
    assert main(["localize", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                 "--format", "json", "-o", str(result)]) == 0  # fmt: skip
    for name, extra in (("a.json", []), ("b.json", ["--result", str(result)])):
        assert main(["update-map", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                     "-o", str(tmp_path / name), *extra]) == 0  # fmt: skip
    a, b = semloc.load_map(tmp_path / "a.json"), semloc.load_map(tmp_path / "b.json")
    assert [(o.id, o.label, sorted(o.extra)) for o in a] == [
        (o.id, o.label, sorted(o.extra)) for o in b
    ]
    np.testing.assert_allclose(a.positions, b.positions, atol=1e-5)


def test_a_bad_result_file_is_one_line_and_nothing_is_written(tmp_path, capsys):
    write_scene(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text('{"status": "localized", "pose": 3, "hypotheses": []}')
    out = tmp_path / "updated.json"
    assert main(["update-map", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                 "-o", str(out), "--result", str(bad)]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert err.startswith("semloc: error:") and "pose" in err and "\n" not in err
    assert not out.exists()


def test_view_draws_an_arrow_per_moved_object(tmp_path, capsys):
    write_scene(tmp_path)
    result = tmp_path / "result.json"
    assert main(["localize", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                 "--format", "json", "-o", str(result)]) == 0  # fmt: skip
    png = tmp_path / "map.png"
    assert main(["view", str(tmp_path / "global.json"), "--result", str(result), "--local",
                 str(tmp_path / "local.json"), "-o", str(png)]) == 0  # fmt: skip
    assert png.stat().st_size > 0

    from semloc.cli.files import read_result
    from semloc.pictures.viz import map_figure, plot_localization

    answer = read_result(result)
    assert answer.moved == (("g4", "l4"),)
    g, local = semloc.load_map(tmp_path / "global.json"), semloc.load_map(tmp_path / "local.json")
    _, ax = map_figure(g.positions[:, :2])
    plot_localization(ax, g, local, answer.pose, answer.pairs, moved=answer.moved)
    from matplotlib.colors import to_rgba

    from semloc.pictures.viz import MOVED_COLOR

    arrows = [t for t in ax.texts if getattr(t, "arrow_patch", None) is not None
              and np.allclose(t.arrow_patch.get_edgecolor(), to_rgba(MOVED_COLOR))]  # fmt: skip
    assert len(arrows) == 1
    start, end = np.array(arrows[0].xyann), np.array(arrows[0].xy)
    np.testing.assert_allclose(start, g.get("g4").position[:2], atol=1e-6)
    assert np.linalg.norm(end - start) > 1.4  # to where the lamp was seen, 1.5 m away


def test_a_bad_moved_entry_in_a_result_file_is_one_line(tmp_path, capsys):
    write_scene(tmp_path)
    bad = tmp_path / "bad.json"
    bad.write_text('{"status": "localized", "pose": null, "hypotheses": [], '
                   '"changes": {"moved": [{"global": "g4"}], "new": [], "missing": []}}')  # fmt: skip
    assert main(["view", str(tmp_path / "global.json"), "--result", str(bad),
                 "-o", str(tmp_path / "x.png")]) == 2  # fmt: skip
    err = capsys.readouterr().err.strip()
    assert "changes.moved[0]" in err and "\n" not in err


def test_the_rerun_recording_gets_the_moved_arrows(tmp_path):
    from semloc.pictures.viz3d import _moved_arrows, write_localization

    g = write_scene(tmp_path)
    local = semloc.load_map(tmp_path / "local.json")
    starts, vectors = _moved_arrows(g, local.transformed(T), [("g4", "l4"), ("g0", "nobody")])
    np.testing.assert_allclose(starts, [g.get("g4").position])
    np.testing.assert_allclose(vectors, [[1.2, -0.9, 0.0]], atol=1e-6)
    path = write_localization(tmp_path / "s.rrd", g, local, T, [], moved=[("g4", "l4")])
    assert path.stat().st_size > 0


def test_a_flagged_object_seen_again_loses_its_flag(tmp_path):
    """The plant was flagged missing; a later view sees it where it stood: the next update
    clears the flag (and keeps the others' fields)."""
    g = write_scene(tmp_path)
    updated = tmp_path / "updated.json"
    assert main(["update-map", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                 "-o", str(updated)]) == 0  # fmt: skip
    assert semloc.load_map(updated).get("g5").extra.get("missing") is True
    semloc.save_map(ObjectMap(seen_from_t(list(g)[:6]), up=[0, 0, 1]), tmp_path / "again.json")
    later = tmp_path / "later.json"
    assert main(["update-map", str(updated), str(tmp_path / "again.json"), "-o", str(later)]) == 0
    plant = semloc.load_map(later).get("g5")
    assert "missing" not in plant.extra
    assert semloc.load_map(later).get("l9").extra["new"] is True


def write_room_with_a_moved_chair(folder, boxes: bool) -> tuple[ObjectMap, int]:
    """A 30-object map without points (with boxes or centres only) and a view of its 9
    central objects in another frame, one chair moved 1.5 m; (the map, the chair's index)."""
    from helpers import room as irregular_room

    sizes = {"chair": [0.5, 0.5, 0.9], "table": [1.4, 0.8, 0.75], "lamp": [0.3, 0.3, 1.5],
             "sofa": [2.0, 0.9, 0.8], "bin": [0.3, 0.3, 0.4], "shelf": [0.4, 1.2, 1.8],
             "plant": [0.4, 0.4, 0.9], "tv": [1.1, 0.1, 0.6]}  # fmt: skip
    rng = np.random.default_rng(1)
    g = irregular_room(30)
    if boxes:
        g = ObjectMap([o.replace(size=sizes[o.label], rotation=yaw_pose(rng.uniform(0, 3))[:3, :3])
                       for o in g], up=[0, 0, 1])  # fmt: skip
    near = np.argsort(np.linalg.norm(g.positions[:, :2] - g.positions[:, :2].mean(axis=0), axis=1))
    chair = next(int(i) for i in near[:9] if g[int(i)].label == "chair")
    to_local = np.linalg.inv(yaw_pose(0.8, [3.0, -2.0, 0.0]))
    seen = []
    for k, i in enumerate(near[:9].tolist()):
        obj = g[i].transformed(yaw_pose(0.0, [1.5, 0.0, 0.0])) if i == chair else g[i]
        seen.append(obj.transformed(to_local).replace(id=f"l{k}", seen=k))
    semloc.save_map(g, folder / "global.json")
    semloc.save_map(ObjectMap(seen, up=[0, 0, 1]), folder / "local.json")
    return g, chair


def test_with_boxes_and_no_points_a_moved_chair_is_moved_not_added(tmp_path, capsys):
    """Maps of boxes without points (issue 44): a chair moved 1.5 m is `moved` and the
    updated map keeps its 30 objects, the chair where it was seen (it was `new`: a 31st
    object, and the old chair left in place)."""
    g, chair = write_room_with_a_moved_chair(tmp_path, boxes=True)
    out = tmp_path / "updated.json"
    assert main(["update-map", str(tmp_path / "global.json"), str(tmp_path / "local.json"),
                 "-o", str(out)]) == 0  # fmt: skip
    assert f"changes, moved: {g[chair].id}" in capsys.readouterr().out
    updated = semloc.load_map(out)
    assert len(updated) == 30 and not any(o.extra.get("new") for o in updated)
    np.testing.assert_allclose(updated.get(g[chair].id).position,
                               g[chair].position + [1.5, 0.0, 0.0], atol=0.05)  # fmt: skip


def test_with_centres_only_the_output_says_a_moved_object_reads_as_new(tmp_path, capsys):
    write_room_with_a_moved_chair(tmp_path, boxes=False)
    assert main(["localize", str(tmp_path / "global.json"), str(tmp_path / "local.json")]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "changes, new: l" in text
    assert ("note: 9 of 9 local objects have neither points nor a box: such an object that "
            "moved reads as new") in text  # fmt: skip

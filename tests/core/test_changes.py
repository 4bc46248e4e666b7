"""What changed (semloc.changes): matched, moved, new and missing objects under a pose."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from test_changes_fixtures import T, cube, room, seen_from_t

import semloc
from semloc.changes import (
    UNDECIDED_KEPT,
    Changes,
    ChangesConfig,
    Moved,
    RunChanges,
    answer_changes,
    apply_changes,
    explain,
)
from semloc.maps import ObjectMap, SemanticObject
from semloc.transforms import pose_error, yaw_pose


def candidates_of(global_map: ObjectMap, local: list[SemanticObject]) -> dict[str, np.ndarray]:
    return {o.id: np.flatnonzero(global_map.labels == o.label) for o in local}


def test_an_unchanged_view_has_no_changes():
    g = room()
    local = seen_from_t(list(g)[:6])
    pairs = [(f"g{i}", f"l{i}") for i in range(4)]  # two more are matched by their place
    changes = explain(g, local, T, pairs, candidates_of(g, local))
    assert changes == Changes()


def test_a_moved_a_new_and_a_missing_object_are_named():
    g = room()
    objects = list(g)[:6]
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))  # the lamp moved 1.5 m
    objects[5] = SemanticObject("g9", "bed", points=cube([4.5, 1.0, 0.4], seed=9))  # new
    # the map's plant (g5, at [4.5, 4.2]) is gone, and the sofa (g3) stands right beside it
    objects.append(SemanticObject("g10", "bin", points=cube([4.0, 3.8, 0.6], seed=10)))
    local = seen_from_t(objects)
    pairs = [(f"g{i}", f"l{i}") for i in range(4)]
    changes = explain(g, local, T, pairs, candidates_of(g, local))
    assert [(m.global_id, m.local_id) for m in changes.moved] == [("g4", "l4")]
    assert abs(changes.moved[0].offset_m - 1.5) < 0.05
    # the map's only bin (g7) stood where nothing was in view: a bin seen elsewhere is new
    assert changes.new == ["l9", "l10"]
    assert changes.missing == ["g5"]


def test_an_object_farther_than_max_offset_is_new_not_moved():
    g = room()
    objects = [*list(g)[:4], SemanticObject("g10", "bin", points=cube([14.0, 9.0, 0.6], seed=10))]
    local = seen_from_t(objects)
    changes = explain(g, local, T, [(f"g{i}", f"l{i}") for i in range(4)], candidates_of(g, local))
    assert changes.moved == [] and changes.new == ["l10"]


def test_objects_without_points_vouch_for_no_missing_object():
    g = room()
    local = [o.replace(points=None) for o in seen_from_t(list(g)[:4])]
    changes = explain(g, local, T, [(f"g{i}", f"l{i}") for i in range(4)], candidates_of(g, local))
    assert changes.missing == []


def test_localize_reports_the_changes_of_its_answer():
    g = room()
    objects = list(g)[:5]
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))
    local = ObjectMap(seen_from_t(objects), up=[0, 0, 1])
    result = semloc.localize(g, local)
    assert result.status != "failed"
    assert [(m.global_id, m.local_id) for m in result.changes.moved] == [("g4", "l4")]
    assert result.to_dict()["changes"]["moved"][0]["global"] == "g4"
    assert (
        semloc.localize(g, ObjectMap(seen_from_t(list(g)[:5]), up=[0, 0, 1])).changes == Changes()
    )


def test_a_result_explains_the_local_map_of_its_own_update():
    """`Result.changes` is computed when first read, from the objects of its update: a later
    update (here a new bed) does not leak into an earlier result."""
    g = room()
    objects = list(g)
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))
    localizer = semloc.Localizer(g, local_up=[0, 0, 1])
    first = localizer.update(seen_from_t(objects))
    later = localizer.update(seen_from_t([SemanticObject("g9", "bed", points=cube([4.5, 1, 0.4]))]))
    assert [m.local_id for m in first.changes.moved] == ["l4"] and first.changes.new == []
    assert later.changes.new == ["l9"]


def _with_chairs(chairs: dict[str, tuple[list[float], float]]) -> ObjectMap:
    """The room without its chair, plus chairs {id: (centre, box edge)}."""
    others = [o for o in room() if o.label != "chair"]
    extra = [SemanticObject(i, "chair", points=cube(c, half=e / 2, seed=7), size=[e, e, e])
             for i, (c, e) in chairs.items()]  # fmt: skip
    return ObjectMap([*others, *extra], up=[0, 0, 1])


def test_a_moved_object_comes_from_the_map_object_of_its_own_size_not_the_nearest():
    g = _with_chairs({"g_small": ([1.0, 3.0, 0.5], 0.40), "g_large": ([2.6, 3.4, 0.5], 0.54)})
    moved = SemanticObject("g_small", "chair", points=cube([2.2, 2.7, 0.5], half=0.2, seed=8),
                           size=[0.4, 0.4, 0.4])  # fmt: skip
    local = seen_from_t([*list(g)[:4], moved])
    pairs = [(o.id, o.id.replace("g", "l")) for o in list(g)[:4]]
    changes = explain(g, local, T, pairs, candidates_of(g, local))
    # the large chair is 0.8 m away, the small one 1.2 m: the box decides (ratio 1.35 < 1.5,
    # so both could be the source)
    assert [(m.global_id, m.local_id) for m in changes.moved] == [("g_small", "l_small")]
    offset = np.linalg.norm(moved.position - g.get("g_small").position)
    assert abs(changes.moved[0].offset_m - offset) < 1e-6


def test_a_moved_object_beside_another_kind_of_object_is_not_taken_for_it():
    """A chair that now stands where the map has a (much larger) table is moved, not the table
    under another name; an object of the same size there would be (a detector's label)."""
    g = _with_chairs({"g_chair": ([2.0, 1.5, 0.5], 0.4)})
    table = next(o for o in g if o.label == "table").replace(size=[1.6, 0.9, 0.8])
    g = g.with_objects([table if o.id == table.id else o for o in g])
    at_table = table.position + [0.3, 0.0, 0.0]
    chair = SemanticObject("g_chair", "chair", points=cube(at_table, half=0.2, seed=8),
                           size=[0.4, 0.4, 0.4])  # fmt: skip
    rest = [o for o in g if o.label in ("lamp", "sofa", "bin")]
    local = seen_from_t([*rest, chair])
    pairs = [(o.id, o.id.replace("g", "l")) for o in rest]
    changes = explain(g, local, T, pairs, candidates_of(g, local))
    assert [(m.global_id, m.local_id) for m in changes.moved] == [("g_chair", "l_chair")]
    relabelled = chair.replace(label="bin", size=[1.6, 0.9, 0.8])  # the table, named 'bin'
    local = seen_from_t([*rest, relabelled])
    changes = explain(g, local, T, pairs, candidates_of(g, local))
    assert changes.moved == [] and changes.new == []


def test_three_matched_objects_beat_two_matched_and_two_moved():
    """Two places fit the view's chair and table; at one the lamp is where the map has it too
    (the bin is new), at the other the lamp and the bin would both have moved 1 m.  Moved
    objects are neither pairs nor support: the place with three matched objects wins, and the
    other keeps its two pairs."""
    here = {"chair": [0, 0, 0.5], "table": [3, 0, 0.4], "lamp": [3, 2.5, 0.8]}
    there = {"chair": [20, 0, 0.5], "table": [23, 0, 0.4], "lamp": [23.8, 3.1, 0.8],
             "bin": [19.4, 3.0, 0.5]}  # fmt: skip
    g = ObjectMap(
        [SemanticObject(f"a_{k}", k, points=cube(p, seed=i)) for i, (k, p) in enumerate(here.items())]
        + [SemanticObject(f"b_{k}", k, points=cube(p, seed=i)) for i, (k, p) in enumerate(there.items())],
        up=[0, 0, 1],
    )  # fmt: skip
    seen = [
        SemanticObject(f"g_{k}", k, points=cube(p, seed=i)) for i, (k, p) in enumerate(here.items())
    ]
    seen.append(SemanticObject("g_bin", "bin", points=cube([0, 2.2, 0.3], seed=9)))
    result = semloc.localize(g, ObjectMap(seen_from_t(seen), up=[0, 0, 1]))
    best, other = result.hypotheses[:2]
    assert sorted(best.pairs) == [
        ("a_chair", "l_chair"),
        ("a_lamp", "l_lamp"),
        ("a_table", "l_table"),
    ]
    assert np.allclose(best.pose, T, atol=0.05)
    assert sorted(other.pairs) == [("b_chair", "l_chair"), ("b_table", "l_table")]
    assert other.features["n_support"] == 0
    assert result.changes.new == ["l_bin"] and result.changes.moved == []


def test_a_moved_object_is_named_with_its_offset_and_is_no_pair():
    """The lamp moved 1.5 m: reported `moved` (1.5 m) and not taken as support for the pose."""
    g = room()
    objects = list(g)[:6]
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))
    result = semloc.localize(g, ObjectMap(seen_from_t(objects), up=[0, 0, 1]))
    assert pose_error(result.pose, T)[0] < 0.1 and pose_error(result.pose, T)[1] < 0.01
    assert result.changes.moved == [Moved("g4", "l4", result.changes.moved[0].offset_m)]
    assert abs(result.changes.moved[0].offset_m - 1.5) < 0.01
    assert result.changes.new == [] and result.changes.missing == []
    assert "l4" not in {l for _, l in result.best.pairs}
    assert sorted(result.best.pairs) == [(f"g{i}", f"l{i}") for i in (0, 1, 2, 3, 5)]
    moved = result.to_dict()["changes"]["moved"]
    assert moved == [{"global": "g4", "local": "l4", "offset_m": pytest.approx(1.5, abs=0.01)}]


def test_a_spurious_detection_is_new_and_no_pair():
    """A bed where the map has none (and no bed anywhere): `new`, not matched, not moved."""
    g = room()
    spurious = SemanticObject("g9", "bed", points=cube([4.5, 1.0, 0.4], seed=9))
    result = semloc.localize(g, ObjectMap(seen_from_t([*list(g)[:5], spurious]), up=[0, 0, 1]))
    assert pose_error(result.pose, T)[0] < 0.1 and pose_error(result.pose, T)[1] < 0.01
    assert result.changes == Changes(new=["l9"])
    assert "l9" not in {l for _, l in result.best.pairs}
    assert result.to_dict()["changes"] == {"moved": [], "new": ["l9"], "missing": []}


def test_a_moved_object_whose_old_place_was_seen_is_moved_not_missing():
    g = room()
    objects = list(g)[:6]
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))  # g4 moved 1.5 m
    objects.append(SemanticObject("g9", "bed", points=cube([1.5, 3.4, 0.9], half=0.3, seed=9)))
    local = seen_from_t(objects)
    pairs = [(f"g{i}", f"l{i}") for i in range(4)]
    changes = explain(g, local, T, pairs, candidates_of(g, local))
    assert [m.global_id for m in changes.moved] == ["g4"]
    assert "g4" not in changes.missing  # its place was seen empty: it is the moved one
    assert set(changes.matched) >= {"g0", "g1", "g2", "g3"}


@settings(max_examples=40)
@given(
    yaw=st.floats(-np.pi, np.pi),
    shift=st.tuples(*[st.floats(-50, 50)] * 2),
    kept=st.lists(st.integers(0, 7), min_size=2, max_size=8, unique=True),
    moved_by=st.tuples(st.floats(-2.0, 2.0), st.floats(-2.0, 2.0)),
)
def test_the_changes_do_not_depend_on_the_local_frame(yaw, shift, kept, moved_by):
    """Whatever frame the robot's local map is in (the pose says where it lies), the same view
    has the same changes; a view of the map's own objects has nothing moved or new."""
    g = room()
    objects = [list(g)[i] for i in sorted(kept)]
    frame = yaw_pose(yaw, [*shift, 0.0])
    pairs = [(o.id, o.id.replace("g", "l")) for o in objects[:2]]
    unchanged = [o.transformed(np.linalg.inv(frame)).replace(id=o.id.replace("g", "l"))
                 for o in objects]  # fmt: skip
    same = explain(g, unchanged, frame, pairs, candidates_of(g, unchanged))
    assert same.moved == [] and same.new == []  # (map objects beside it may be missing)
    objects[-1] = objects[-1].transformed(yaw_pose(0.0, [*moved_by, 0.0]))
    reference = seen_from_t(objects)
    expected = explain(g, reference, T, pairs, candidates_of(g, reference))
    local = [o.transformed(np.linalg.inv(frame)).replace(id=o.id.replace("g", "l"))
             for o in objects]  # fmt: skip
    found = explain(g, local, frame, pairs, candidates_of(g, local))
    assert found.new == expected.new and found.missing == expected.missing
    assert [(m.global_id, m.local_id) for m in found.moved] == [
        (m.global_id, m.local_id) for m in expected.moved
    ]
    for a, b in zip(found.moved, expected.moved):
        assert a.offset_m == pytest.approx(b.offset_m, abs=1e-6)


def boxes_only(objects: list[SemanticObject]) -> list[SemanticObject]:
    """The objects with a box (0.4 m, turned 0.3 rad) and no points: a map of boxes."""
    rotation = yaw_pose(0.3)[:3, :3]
    return [o.replace(points=None, size=[0.4, 0.4, 0.4], rotation=rotation) for o in objects]


def test_with_boxes_and_no_points_a_moved_object_is_moved_not_new():
    """Without points, the boxes say where the view saw surfaces: the lamp's old place beside
    them was in view, so the lamp seen 1.5 m away moved (it read as new), and the plant whose
    place beside the bin's box was seen is missing."""
    g = ObjectMap(boxes_only(list(room())), up=[0, 0, 1])
    objects = list(g)[:6]
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))  # the lamp moved 1.5 m
    objects[5] = SemanticObject("g9", "bed", [4.5, 1.0, 0.4], size=[0.4, 0.4, 0.4])  # new
    objects.append(SemanticObject("g10", "bin", [4.0, 3.8, 0.6], size=[0.4, 0.4, 0.4]))
    local = seen_from_t(objects)
    pairs = [(f"g{i}", f"l{i}") for i in range(4)]
    changes = explain(g, local, T, pairs, candidates_of(g, local))
    assert [(m.global_id, m.local_id) for m in changes.moved] == [("g4", "l4")]
    assert abs(changes.moved[0].offset_m - 1.5) < 0.05
    assert changes.new == ["l9", "l10"] and changes.missing == ["g5"]


def test_with_centres_only_a_moved_object_reads_as_new():
    """A centre alone says nothing about what was in view: the bound, documented."""
    g = room()
    objects = list(g)[:5]
    objects[4] = objects[4].transformed(yaw_pose(0.0, [1.2, -0.9, 0.0]))
    local = [o.replace(points=None) for o in seen_from_t(objects)]
    changes = explain(g, local, T, [(f"g{i}", f"l{i}") for i in range(4)], candidates_of(g, local))
    assert changes.moved == [] and changes.new == ["l4"] and changes.missing == []


# The run's change report (RunChanges) at its rules -------------------------------------------
def test_a_new_object_seen_twice_is_reported_and_a_later_sighting_in_place_cancels_it():
    ids = ["g0", "g1", "g2"]
    run = RunChanges()
    run.observe_new("l5", seen=3)
    assert run.report(ids).new == []  # once: a phantom or a mislabel
    run.observe_new("l5", seen=4)
    assert run.report(ids).new == ["l5"] and run.report(ids).evidence["new"] == {"l5": 2}
    run.observe_matched(0, "l5")  # the same detection found its map object after all
    assert run.report(ids).new == [] and not run


def test_a_run_with_only_missing_evidence_has_changes_and_reports_them_with_their_counts():
    ids = ["g0", "g1", "g2"]
    run = RunChanges()
    assert not run
    run.observe_missing([2])
    assert run  # one look already counts as evidence, though not yet as a change
    run.observe_missing([2])
    run.observe_matched(1, "l1")
    report = run.report(ids)
    assert report.missing == ["g2"] and report.matched == ["g1"]
    assert report.evidence == {"new": {}, "missing": {"g2": 2}}


def test_a_run_s_report_round_trips_through_its_state_and_an_empty_state_is_an_empty_run():
    ids = ["g0", "g1", "g2", "g3"]
    run = RunChanges()
    for seen in (3, 4):
        run.observe_moved(1, "l1", 2.0 + seen / 10, seen=seen)
        run.observe_new("l7", seen=seen)
        run.observe_missing([2])
    run.observe_matched(3, "l3")
    run.observe_undecided("l8", {0: 1.5, 2: 2.5}, seen=5)
    state = json.loads(json.dumps(run.state(ids)))
    assert set(state) == {"moved", "new", "missing", "matched", "undecided"}
    restored = RunChanges.restored(state, ids.index)
    assert restored.state(ids) == state
    assert restored.report(ids).to_dict() == run.report(ids).to_dict()
    assert restored.report(ids).matched == ["g3"]
    empty = RunChanges.restored({}, ids.index)
    assert not empty and empty.report(ids).matched == []


def test_an_undecided_move_counts_for_the_source_left_once_the_others_are_seen_in_place():
    ids = ["g0", "g1", "g2"]
    run = RunChanges()
    run.observe_undecided("l5", {0: 1.2, 1: 2.0}, seen=3)
    run.observe_undecided("l5", {0: 1.1, 1: 2.1}, seen=4)
    assert run and run.report(ids).moved == []  # g0 or g1: cannot be told
    run.observe_matched(0, "l0")  # g0 stands at its place: l5 came from g1, twice
    assert [(m.global_id, m.local_id, m.offset_m, m.evidence, m.last_seen)
            for m in run.report(ids).moved] == [("g1", "l5", 2.1, 2, 4)]  # fmt: skip
    run.observe_undecided("l6", {0: 1.0, 2: 2.0}, seen=5)  # g0 seen in place: one left
    assert run.moved[2][2] == 1 and not run.undecided
    run.observe_matched(1, "l1")  # and all sources seen in place: nothing left to decide
    assert [m.global_id for m in run.report(ids).moved] == []


def test_the_undecided_detections_kept_are_the_latest_ones():
    run = RunChanges()
    for seen in range(UNDECIDED_KEPT + 5):
        run.observe_undecided("l5", {0: 1.0, 1: 2.0}, seen=seen)
    run.observe_undecided("l6", {0: 1.0, 2: 2.0}, seen=UNDECIDED_KEPT + 5)
    run.observe_matched(2, "l2")  # decides l6's detection, and keeps the latest others
    assert len(run.undecided) == UNDECIDED_KEPT - 1 and run.undecided[0][2] == 6
    assert run.moved[0][2] == 1 and run.undecided.maxlen == UNDECIDED_KEPT


@pytest.mark.parametrize("least", [1, 3])
def test_a_restored_report_keeps_the_evidence_it_was_given(least):
    ids = ["g0", "g1"]
    run = RunChanges(least)
    for seen in (3, 4):
        run.observe_moved(1, "l1", 2.0, seen=seen)
    restored = RunChanges.restored(json.loads(json.dumps(run.state(ids))), ids.index, least)
    assert restored.min_evidence == least
    assert restored.report(ids).moved == run.report(ids).moved
    assert bool(restored.report(ids).moved) is (least <= 2)


# The single view's rules at their bounds (identity pose, one map chair at the origin) -----------
def one_chair() -> ObjectMap:
    return ObjectMap([SemanticObject("g0", "chair", [0, 0, 0], size=[0.5, 0.5, 0.5])], up=[0, 0, 1])


def observer(x: float, y: float) -> SemanticObject:
    """A detection of another kind whose one observed point is at (x, y, 0)."""
    return SemanticObject("l9", "bin", [x, y, 0], points=np.array([[x, y, 0.0]]))


def changes_of(local: list[SemanticObject], config: ChangesConfig | None = None) -> Changes:
    cands = {o.id: np.array([0] if o.label == "chair" else [], dtype=int) for o in local}
    return explain(one_chair(), local, np.eye(4), [], cands, config)


def test_an_object_is_matched_within_the_match_radius_not_at_it():
    assert changes_of([SemanticObject("l0", "chair", [0.49, 0, 0])]).new == []
    assert changes_of([SemanticObject("l0", "chair", [0.5, 0, 0])]).new == ["l0"]


def test_an_object_moved_exactly_the_largest_offset_from_a_seen_place_is_moved():
    seen = observer(0.0, 1.4)  # the chair's old place within the source radius (1.5 m): seen
    chair = SemanticObject("l0", "chair", [3.0, 0, 0], size=[0.75, 0.75, 0.75])  # 1.5 x larger
    changes = changes_of([chair, seen])
    assert [(m.global_id, m.offset_m) for m in changes.moved] == [("g0", 3.0)]
    assert changes.new == ["l9"] and changes.missing == []
    assert changes_of([chair.replace(position=[3.01, 0, 0]), seen]).moved == []  # too far
    assert changes_of([chair.replace(size=[0.76, 0.76, 0.76]), seen]).moved == []  # too large
    assert changes_of([chair, observer(0.0, 1.51)]).moved == []  # the old place unseen
    # exactly at the source radius still counts as seen (a wider observed radius lets the
    # search of observed points reach that far)
    wide = ChangesConfig(observed_radius=2.0)
    assert [m.global_id for m in changes_of([chair, observer(0.0, 1.5)], wide).moved] == ["g0"]


def test_a_map_object_is_missing_when_a_point_was_observed_within_the_radius_of_its_place():
    assert changes_of([observer(0.5, 0.0)]).missing == ["g0"]
    assert changes_of([observer(0.51, 0.0)]).missing == []


def test_a_local_object_without_candidates_is_new():
    chair = SemanticObject("l0", "chair", [0.1, 0, 0], size=[2.0, 2.0, 2.0])
    assert explain(one_chair(), [chair], np.eye(4), [], {}).new == ["l0"]


def test_an_object_of_another_size_at_its_place_is_matched_one_to_one():
    # boxes twice the map chair's: at its place a chair is that chair (the detector's box), not
    # a moved one; a second chair beside it is not explained by the same map object
    big = [1.0, 1.0, 1.0]
    first = SemanticObject("l0", "chair", [0.1, 0, 0], size=big)
    second = SemanticObject("l1", "chair", [0.2, 0, 0], size=big)
    assert changes_of([first]).new == []
    assert changes_of([first, second]).new == ["l1"]


def test_a_relabelled_object_takes_the_nearest_map_object_at_its_place_only():
    g = ObjectMap(
        [SemanticObject("g0", "chair", [0, 0, 0], size=[0.5] * 3),
         SemanticObject("g1", "table", [5, 0.4, 0], size=[0.5] * 3),
         SemanticObject("g2", "shelf", [5, -0.1, 0], size=[0.5] * 3)],
        up=[0, 0, 1],
    )  # fmt: skip
    chair = SemanticObject("l0", "chair", [0.1, 0, 0])  # matched at its place first
    stool = SemanticObject("l1", "stool", [5, 0, 0], size=[0.5] * 3, points=np.array([[5, 0, 0.0]]))
    changes = explain(
        g, [chair, stool], np.eye(4), [], {"l0": np.array([0]), "l1": np.array([], dtype=int)}
    )
    # the stool is the shelf under another name (0.1 m); the table, 0.4 m from the observed
    # point, stood in view and nobody explains it
    assert changes.new == [] and changes.missing == ["g1"]


def test_every_observed_point_counts_even_for_an_object_of_two():
    two = SemanticObject("l9", "bin", [3.0, 0, 0], points=np.array([[3.0, 0, 0], [0.4, 0, 0]]))
    assert changes_of([two]).missing == ["g0"]


def test_a_box_is_observed_on_its_surface_as_it_is_turned():
    # a 2 m long thin box 1 m from the chair, turned a quarter turn: its end reaches the chair
    turned = yaw_pose(np.pi / 2, [0, 0, 0])[:3, :3]
    long = SemanticObject("l9", "bin", [0, 1.0, 0], size=[2.0, 0.1, 0.1], rotation=turned)
    assert changes_of([long]).missing == ["g0"]
    assert changes_of([long.replace(rotation=None)]).missing == []  # along x: 1 m away


def test_an_answer_s_changes_keep_only_the_pairs_of_both_maps_and_its_settings():
    g = one_chair()
    chair = SemanticObject("l0", "chair", [0.4, 0, 0])
    cands = {"l0": np.array([0])}
    pairs = [("g0", "l0"), ("gx", "l0"), ("g0", "lx")]
    assert answer_changes(g, [chair], np.eye(4), pairs, candidates=cands) == Changes()
    assert answer_changes(g, [chair], np.eye(4), [("gx", "l0")], candidates=cands) == Changes()
    tight = ChangesConfig(match_radius=0.3)
    assert answer_changes(g, [chair], np.eye(4), [], config=tight, candidates=cands).new == ["l0"]


def test_a_run_s_changes_round_trip_through_their_document_with_their_evidence():
    run = RunChanges()
    for seen in (3, 4):
        run.observe_moved(0, "l1", 1.23456789, seen=seen)
        run.observe_new("l7", seen=seen)
        run.observe_missing([1])
    report = run.report(["g0", "g1"])
    document = json.loads(json.dumps(report.to_dict()))
    assert document == {
        "moved": [
            {"global": "g0", "local": "l1", "offset_m": 1.234568, "evidence": 2, "last_seen": 4}
        ],
        "new": ["l7"],
        "missing": ["g1"],
        "evidence": {"new": {"l7": 2}, "missing": {"g1": 2}},
    }
    again = Changes.from_dict(document)
    assert again.to_dict() == document and again.moved[0] == Moved("g0", "l1", 1.234568, 2, 4)
    plain = Changes([Moved("g0", "l1", 0.5)], ["l2"], ["g3"])
    assert plain.to_dict() == {
        "moved": [{"global": "g0", "local": "l1", "offset_m": 0.5}], "new": ["l2"], "missing": ["g3"]
    }  # fmt: skip
    assert Changes.from_dict(plain.to_dict()) == plain and Changes.from_dict({}) == Changes()


@pytest.mark.parametrize(
    "document",
    [{"moved": [{"global": "g0"}]}, {"moved": 5}, {"evidence": {"new": 3}},
     {"moved": [{"global": "g0", "local": "l", "offset_m": "far"}]}],
)  # fmt: skip
def test_a_document_that_is_not_a_changes_object_is_refused_in_one_line(document):
    with pytest.raises(ValueError, match=r"^'changes' is not a changes object \("):
        Changes.from_dict(document)


def test_applying_changes_moves_points_with_their_object_and_adds_new_ones_under_free_ids():
    pts = np.array([[0.0, 0, 0], [0.2, 0, 0]])
    prior = ObjectMap(
        [SemanticObject("a", "chair", [0.1, 0, 0], points=pts),
         SemanticObject("b", "sofa", [10, 0, 0]), SemanticObject("new:b", "lamp", [9, 0, 0]),
         SemanticObject("gone", "bin", [5, 0, 0], extra={"missing": True})],
        up=[0, 0, 1],
    )  # fmt: skip
    local = ObjectMap(
        [SemanticObject("la", "chair", [2.1, 0, 0]), SemanticObject("a", "tv", [7, 0, 0]),
         SemanticObject("new:a", "tv", [8, 0, 0]), SemanticObject("b", "tv", [6, 0, 0])],
        up=[0, 0, 1],
    )  # fmt: skip
    changes = Changes([Moved("a", "la", 2.0)], ["a", "new:a", "b"], [])
    updated = {o.id: o for o in apply_changes(prior, local, np.eye(4), changes)}
    moved = updated["a"]
    assert np.allclose(moved.position, [2.1, 0, 0]) and np.allclose(moved.points[:, 0], [2.0, 2.2])
    assert moved.extra["moved_from"] == [0.1, 0, 0] and moved.extra["moved_m"] == 2.0
    # "a" is taken: new:a; "new:a" then is taken too: new:new:a; "b" and new:b are taken: new2:b
    assert {"new:a", "new:new:a", "new2:b"} <= set(updated)
    assert updated["new2:b"].extra["new"] is True and updated["new2:b"].label == "tv"
    assert updated["gone"].extra["missing"] is True  # not seen again: still flagged

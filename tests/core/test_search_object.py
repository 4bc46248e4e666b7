"""The Localizer composes parts that each own their state: what was seen (`Sightings`), the
search (`Search`) and the tracked place (`Track`).  `add` feeds without answering and
`update` always answers; the deprecated `update(..., answer=False)` still works, as `add`; a
search stands on its own; a state round trip keeps everything but the search's sets, which
regrow from the window."""

from __future__ import annotations

import json
from dataclasses import replace

import numpy as np
import pytest

from semloc import Coverage, Localizer, LocalizerConfig, ObjectMap, Result, SemanticObject
from semloc.map_context import MapContext
from semloc.results import Hypothesis
from semloc.search import Search
from semloc.sightings import Sightings
from semloc.sim.layouts import layout
from semloc.sim.longwalk import LongWalk, WalkConfig, World, tiled
from semloc.transforms import yaw_pose

UP = [0, 0, 1]


@pytest.fixture(scope="module")
def hard_walk():
    """A building of three look-alike rooms and a walk through an old map with a detector's
    errors, a kidnap and a carry into a copy, the sensor's coverage given."""
    building = tiled(layout(40, seed=3, points_per_object=60), 3, 1, keep=0.7, seed=3)
    world = World(moved=0.2, gone=0.1, phantoms=0.3, split=0.05, merged=0.05)
    config = WalkConfig(keyframes=80, kidnap_at=30, lookalike_at=55, world=world,
                        wrong_label_rate=0.1, points_per_object=60)  # fmt: skip
    walk = list(LongWalk(building, replace(config, redetections=config.max_visible), seed=3))
    return building, walk


def _answer(result: Result) -> str:
    """The answer's JSON without its timing (which differs from run to run)."""
    document = result.to_dict()
    document.pop("timing_ms", None)
    for step in document["steps"]:
        step.pop("ms")
    return json.dumps(document, sort_keys=True)


def _state(localizer: Localizer) -> str:
    state = localizer.state()
    state.pop("timing")
    for step in state["steps"]:
        step.pop("ms")
    return json.dumps(state, sort_keys=True)


def test_add_then_update_answers_as_the_deprecated_update_without_an_answer(hard_walk):
    building, walk = hard_walk
    new, old = (Localizer(building, LocalizerConfig(), local_up=UP) for _ in range(2))
    statuses = set()
    for k, frame in enumerate(walk):
        given = {"position": frame.T_odom_robot, "coverage": frame.coverage}
        if k % 3 == 1:  # answers read at two updates in three
            assert new.add(frame.objects, **given) is None
            with pytest.warns(DeprecationWarning, match="Localizer.add"):
                assert old.update(frame.objects, answer=False, **given) is None
        else:
            answer = new.update(frame.objects, **given)
            assert isinstance(answer, Result)
            assert _answer(answer) == _answer(old.update(frame.objects, **given))
            statuses.add(answer.status)
        assert _state(new) == _state(old)
    assert {"localized", "ambiguous"} <= statuses  # (the walk reaches both)


def test_update_answers_at_every_update_while_tracking_and_searching(hard_walk):
    building, walk = hard_walk
    localizer = Localizer(building, LocalizerConfig(), local_up=UP)
    tracked = []
    for frame in walk:
        followed = localizer.tracking
        answer = localizer.update(frame.objects, position=frame.T_odom_robot,
                                  coverage=frame.coverage)  # fmt: skip
        assert isinstance(answer, Result) and answer.steps[-1].status == answer.status
        tracked.append(localizer.tracking)
        if localizer.tracking:  # the search is let go while a place is tracked
            assert localizer.n_sets == 0
            assert answer.support.tracked == followed  # (the search's answer starts it)
    assert any(tracked) and not all(tracked)


def test_a_restored_localizer_answers_as_one_whose_search_regrows_from_its_window(hard_walk):
    """A state round trip keeps the window, its looks, the tracked place and its copies, the
    run's changes and rates; the search's sets regrow from the window, as the Localizer's own
    do when its search is renewed (here by setting its prior again)."""
    building, walk = hard_walk
    kept, restored, statuses = Localizer(building, LocalizerConfig(), local_up=UP), None, set()
    for k, frame in enumerate(walk):
        if k in (20, 40, 65):
            state = json.loads(json.dumps(kept.state()))
            restored = Localizer.restore(building, state, kept.window.objects, local_up=UP)
            assert _state(restored) == _state(kept)
            kept.set_prior(kept.prior)  # the search regrows from the window, as restored's
        given = {"position": frame.T_odom_robot, "coverage": frame.coverage}
        answer = kept.update(frame.objects, **given)
        if restored is not None:
            assert _answer(restored.update(frame.objects, **given)) == _answer(answer)
            statuses.add((answer.status, kept.tracking))
    assert {("localized", True), ("ambiguous", False)} <= statuses


def test_a_search_on_its_own_answers_as_the_localizer_that_holds_it():
    building = layout(60, seed=4)
    T = yaw_pose(0.7, [1.5, -2.0, 0.0])
    inverse = np.linalg.inv(T)
    view = [building[i].transformed(inverse).replace(id=f"l{i}", seen=0) for i in range(8, 15)]
    config = LocalizerConfig(track=False)
    context = MapContext(building, config, None)
    sightings = Sightings(context, config.window)
    search = Search(context, sightings, None, np.asarray(building.up))
    objects, _ = sightings.add(view, None, None)
    search.cluster(search.associate(objects))
    hypotheses = search.hypotheses()
    status, _ = search.decide(hypotheses)
    answer = Localizer(building, config, local_up=building.up).update(view)
    assert status == answer.status == "localized"
    assert [h.pairs for h in hypotheses[: config.top_k]] == [h.pairs for h in answer.hypotheses]
    np.testing.assert_allclose(hypotheses[0].pose, T, atol=1e-6)


def test_a_renewed_search_keeps_its_map_prior_and_retrieval_and_nothing_else():
    building = ObjectMap([SemanticObject(f"c{k}", "chair", [k, 0.0, 0.5]) for k in range(5)],
                         up=UP)  # fmt: skip
    config = LocalizerConfig()
    context = MapContext(building, config, None)
    sightings = Sightings(context, config.window)
    search = Search(context, sightings, None, np.asarray(UP), retrieved={"x": np.arange(2)})
    objects, _ = sightings.add(list(building), None, None)
    search.cluster(search.associate(objects))
    search.stale, search.cut = True, (True, 3)
    renewed = search.renewed()
    assert search.n_sets > 0 and renewed.n_sets == 0 and not renewed.local
    assert renewed.context is context and renewed.sightings is sightings
    assert renewed.retrieved is search.retrieved and renewed.prior is None
    assert not renewed.stale and renewed.cut == (False, 0) and renewed.poses == {}


def test_what_is_read_off_a_map_is_shared_by_its_localizers_and_read_only():
    building = layout(60, seed=4)
    one, two = (MapContext(building, LocalizerConfig(), None) for _ in range(2))
    assert one.tree is two.tree and one.twin_index is two.twin_index and one.codes is two.codes
    assert one.allowances is two.allowances and one.parts is two.parts
    with pytest.raises(ValueError, match="read-only"):
        one.parts[0] = 1.0  # (one Localizer must not change another's)
    looser = MapContext(building, LocalizerConfig(track_tolerance=0.9), None)
    assert looser.allowances is not one.allowances and looser.tree is one.tree
    assert (looser.allowances > one.allowances).all()
    again = MapContext(building.with_objects(list(building)), LocalizerConfig(), None)
    assert again.tree is not one.tree  # (another map object: its own)
    np.testing.assert_array_equal(again.allowances, one.allowances)


def chairs_seen(*travel: float) -> Sightings:
    """A row of five chairs, one seen at each update, the robot at `travel` m along x."""
    building = ObjectMap([SemanticObject(f"c{k}", "chair", [k, 0.0, 0.5]) for k in range(5)],
                         up=UP)  # fmt: skip
    config = LocalizerConfig()
    sightings = Sightings(MapContext(building, config, None), config.window)
    for k, x in enumerate(travel):
        sightings.add([building[k].replace(id=f"l{k}")], np.array([x, 0.0, 0.0]), None)
    return sightings


@pytest.mark.parametrize(("walked", "stale"), [(2.0, False), (np.nextafter(2.0, 3), True)])
def test_a_claim_is_stale_only_past_stale_m_beyond_its_latest_detection(walked, stale):
    """Stale: none of the objects detected within `stale_m` m of travel, judged on the newest
    of their detections; exactly `stale_m` away is not stale yet."""
    sightings = chairs_seen(0.0, 1.0, 1.0 + walked)  # l0 at 0 m, l1 at 1 m, l2 at 1 + walked
    assert sightings.stale(["l0", "l1"], 2.0) == stale
    assert sightings.stale(["l1", "l0"], 2.0) == stale  # (whatever their order)
    assert not sightings.stale(["l0", "l1"], None)  # no distance: never stale
    assert not sightings.stale(["l2"], 0.0)  # detected now


def test_a_claim_on_no_object_in_the_window_is_stale():
    sightings = chairs_seen(0.0, 1.0)
    assert sightings.stale(["gone"], 100.0) and sightings.stale([], 100.0)
    assert not sightings.stale(["gone", "l1"], 100.0)  # (an object left counts)
    assert not sightings.stale(["gone"], None)


@pytest.mark.parametrize("updates", [1, 2, 3])
def test_keep_latest_keeps_the_objects_of_exactly_the_latest_updates(updates):
    sightings = chairs_seen(0.0, 1.0, 2.0, 3.0)
    sightings._unseen_of = {"cached": (np.zeros(0), np.zeros(0))}
    sightings.keep_latest(updates)
    kept = [f"l{k}" for k in range(4 - updates, 4)]
    assert [o.id for o in sightings.window.objects] == kept
    assert sorted(sightings.found) == kept and sightings._unseen_of == {}


def ring_seen(*looks: Coverage) -> Sightings:
    """53 chairs on a ring of 8 m about the robot, the first of them detected (as `l0`,
    keyframe 7) at the first update; each update with one of `looks`, nothing new after."""
    angles = np.arange(53) * 2 * np.pi / 53
    building = ObjectMap([SemanticObject(f"c{k:02d}", "chair", [8 * np.cos(a), 8 * np.sin(a), 0.5])
                          for k, a in enumerate(angles)], up=UP)  # fmt: skip
    config = LocalizerConfig()
    sightings = Sightings(MapContext(building, config, None), config.window)
    sightings.add([building[0].replace(id="l0", seen=7)], np.zeros(3), looks[0])
    for look in looks[1:]:
        sightings.add([], np.zeros(3), look)
    return sightings


def best_of(pairs: list[tuple[str, str]], **given) -> Hypothesis:
    return Hypothesis(rank=1, score=1.0, pairs=pairs, **{"pose": np.eye(4), **given})


def test_the_support_names_the_first_missing_ids_kept_of_the_map_objects_missing():
    """52 of the 53 chairs the look expects are missing: the best place's support names the
    first `MISSING_IDS_KEPT` (50) in the map's order, and counts them all."""
    sightings = ring_seen(Coverage(np.eye(4), 12.0))
    best = best_of([("c00", "l0"), ("c01", "gone")])  # (a pair that left the window: none)
    support = sightings.support_of(best, None)
    assert support.n_missing == best.n_missing == 52 and support.n_expected == 53
    assert support.missing_ids == tuple(f"c{k:02d}" for k in range(1, 51))
    assert support.n_pairs == 1 and support.seen == (7, 7) and not support.tracked


def test_a_tracked_support_is_of_this_updates_look_when_its_missing_ones_are_weighed():
    """Tracked, with this update's look (expecting nothing) and the best place weighed: the
    look names no missing object; untracked or unweighed, the support takes every look kept."""
    everything, nothing = Coverage(np.eye(4), 12.0), Coverage(np.eye(4), 0.1)
    sightings = ring_seen(everything, nothing)
    weighed = best_of([("c00", "l0")], n_missing=5, n_expected=9)
    tracked = sightings.support_of(weighed, {"changed": 2, "contradicting": 3})
    assert tracked.missing_ids == () and (tracked.n_missing, tracked.n_expected) == (5, 9)
    assert tracked.tracked and (tracked.n_changed, tracked.n_contradicting) == (2, 3)
    untracked = sightings.support_of(weighed, None)
    assert len(untracked.missing_ids) == 50
    assert (untracked.n_missing, untracked.n_expected) == (5, 9)
    assert (untracked.n_changed, untracked.n_contradicting) == (0, 0)
    unweighed = sightings.support_of(best_of([("c00", "l0")]), {})
    assert (unweighed.n_missing, unweighed.n_expected) == (52, 53) and unweighed.tracked
    sightings.add([], np.zeros(3), None)  # an update without a look: every look kept
    assert len(sightings.support_of(weighed, {}).missing_ids) == 50


def test_the_support_dates_its_evidence_by_its_oldest_detection():
    """How many updates and metres ago the oldest of the best place's detections was, and
    the keyframes of its detections; no support without a pose or a pair in the window."""
    sightings = chairs_seen(0.0, 1.0, 2.0, 3.5)
    objects = {o.id: o for o in sightings.window.objects}
    sightings.register([objects["l1"].replace(seen=11), objects["l2"].replace(seen=12)])
    support = sightings.support_of(best_of([("c2", "l2"), ("c1", "l1")]), None)
    assert (support.n_pairs, support.seen) == (2, (11, 12))
    assert (support.updates_ago, support.metres) == (2, 2.5)
    assert support.n_missing is None and support.missing_ids is None  # (no look given)
    assert sightings.support_of(None, None) is None
    assert sightings.support_of(best_of([("c2", "l2")], pose=None), None) is None
    assert sightings.support_of(best_of([("c9", "gone")]), None) is None

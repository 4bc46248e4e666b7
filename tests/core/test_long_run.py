"""Long runs: the bounded window, tracking with drifting odometry, kidnaps, bounded results."""

from __future__ import annotations

import json

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from semloc import Localizer, LocalizerConfig, ObjectMap, SemanticObject
from semloc.sim.layouts import layout
from semloc.sim.longwalk import Drift, LongWalk, WalkConfig, World
from semloc.tracking import CONTRADICTED, Track, TrackingConfig, Verdict, allowances, check
from semloc.window import LocalWindow, WindowConfig


def obj(i: int, x: float = 0.0) -> SemanticObject:
    return SemanticObject(f"o{i}", "chair", [x, 0.0, 0.0])


# The window --------------------------------------------------------------------------------
def test_window_retires_the_oldest_beyond_its_count():
    window = LocalWindow(WindowConfig(objects=8))
    window.advance(None)
    window.add([obj(i) for i in range(8)])
    assert window.retire() == []
    window.advance(None)
    window.add([obj(8)])
    assert window.retire() == ["o0", "o1", "o2"]  # down to 6 = 3/4 of the bound
    assert [o.id for o in window.objects] == ["o3", "o4", "o5", "o6", "o7", "o8"]


def test_an_id_sent_again_replaces_its_object_and_counts_as_new():
    window = LocalWindow(WindowConfig(objects=4))
    window.advance(None)
    window.add([obj(i) for i in range(4)])
    window.advance(None)
    window.add([obj(0, x=5.0)])
    assert len(window) == 4 and [o.id for o in window.objects] == ["o1", "o2", "o3", "o0"]
    assert window.objects[-1].position[0] == 5.0 and window.arrival("o0").update == 2
    window.advance(None)
    window.add([obj(4)])
    assert window.retire() == ["o1", "o2"]  # o0 was renewed


def test_window_retires_objects_detected_longer_ago_than_its_distance():
    window = LocalWindow(WindowConfig(objects=None, distance=10.0))
    for k in range(30):
        window.advance(np.array([k * 1.0, 0.0, 0.0]))  # one metre per update
        window.add([obj(k)])
        window.retire()
        oldest = window.arrival(window.objects[0].id).travel
        assert window.travel - oldest <= 10.0
    assert window.travel == 29.0 and len(window) < 12


def walked(window: LocalWindow, *stops: tuple[float, list[SemanticObject]]) -> None:
    """Updates at these odometry x positions (metres along a line), each adding its objects."""
    for x, objects in stops:
        window.advance(np.array([x, 0.0, 0.0]))
        window.add(objects)


def test_an_object_detected_exactly_the_distance_ago_stays_and_just_beyond_it_retires():
    window = LocalWindow(WindowConfig(objects=None, distance=8.0))
    walked(window, (0.0, [obj(0)]), (3.0, [obj(1)]), (8.0, []))
    assert window.retire() == []  # o0 was detected 8 m ago: at the bound, not beyond it
    walked(window, (8.5, []))
    assert window.retire() == ["o0"]  # 8.5 m ago: beyond; the cut keeps 6 m (o1, 5.5 m ago)


def test_an_object_detected_at_the_cut_of_the_distance_bound_is_kept():
    # beyond the bound the window keeps the last 3/4 of it: 6 of 8 m, an object at 6 m included
    window = LocalWindow(WindowConfig(objects=None, distance=8.0))
    walked(window, (0.0, [obj(0)]), (2.0, [obj(1)]), (3.0, [obj(2)]), (9.0, []))
    assert window.retire() == ["o0", "o1"]  # 9 and 7 m ago; o2, 6 m ago, stays
    assert [o.id for o in window.objects] == ["o2"]


def test_the_distance_bound_counts_the_metres_since_the_detection_not_since_the_start():
    window = LocalWindow(WindowConfig(objects=None, distance=6.0))
    walked(window, (0.0, []), (5.0, [obj(0)]), (10.0, [obj(1)]))
    assert window.retire() == []  # o0 was detected 5 m ago (at 5 m of 10 travelled)


def test_without_a_distance_bound_the_count_bound_alone_retires_the_oldest():
    window = LocalWindow(WindowConfig(objects=4, distance=None))
    walked(window, (0.0, [obj(i) for i in range(4)]), (100.0, [obj(4)]))
    assert window.retire() == ["o0", "o1"]  # down to 3 = 3/4 of 4, however far it walked
    assert [o.id for o in window.objects] == ["o2", "o3", "o4"]


def test_a_restored_window_keeps_its_bounds_travel_and_arrivals():
    window = LocalWindow(WindowConfig(objects=4, distance=None))
    walked(window, (0.0, [obj(0), obj(1)]), (3.0, [obj(2)]))
    restored = LocalWindow.restored(window.config, window.state(), window.objects)
    assert restored.state() == window.state() and restored.config == window.config
    walked(restored, (4.0, [obj(3), obj(4)]))
    assert restored.retire() == ["o0", "o1"]  # its own bound of 4 objects, not the default 80
    with pytest.raises(ValueError, match=r"^the window.s objects are not those of its state$"):
        LocalWindow.restored(window.config, window.state(), window.objects[:2])


def test_localizer_window_and_steps_stay_bounded():
    building = layout(120, seed=3)
    localizer = Localizer(building, window={"objects": 10, "steps": 4}, local_up=[0, 0, 1])
    result = None
    for k in range(30):
        result = localizer.update([building[k].replace(id=f"l{k}", seen=k)])
    assert result is not None
    assert len(localizer.local_map) <= 10 and len(result.steps) == 4
    assert [s.step for s in result.steps] == [26, 27, 28, 29]
    localizer.update([building[29].replace(id="l29", seen=30)])  # re-detection: replaces
    assert len(localizer.local_map) <= 10
    assert sum(o.id == "l29" for o in localizer.local_map) == 1


def test_the_settings_are_checked_and_unbounded_is_the_papers_local_map():
    assert LocalizerConfig(objects=30).window.objects == 30
    assert LocalizerConfig(track=False).tracking.track is False
    with pytest.raises(ValueError):
        LocalizerConfig(window={"objects": 1})
    assert WindowConfig.unbounded() == WindowConfig(objects=None, distance=None, steps=None)


# Tracking ----------------------------------------------------------------------------------
def test_check_supports_objects_that_land_on_a_same_label_candidate():
    globals_ = np.array([[0.0, 0.0, 0.0], [5.0, 0.0, 0.0]])
    pose = np.eye(4)
    pose[:3, 3] = [1.0, 0.0, 0.0]
    near, far = obj(1, x=-0.8), obj(2, x=2.0)
    verdict = check(pose, [near, far], {"o1": np.array([0, 1]), "o2": np.array([0])},
                    globals_, allowance=np.array([0.5, 0.5]))  # fmt: skip
    assert verdict.supported == [(0, "o1")] and verdict.contradicting == ["o2"]


def test_one_moved_object_does_not_end_a_claim_but_a_majority_does():
    config = TrackingConfig()
    track = Track(np.eye(4), [(0, "a"), (1, "b"), (2, "c")], 0.99, 3.0, config)
    assert track.contradicted(Verdict([(3, "d"), (4, "e")], ["f"])) == 0
    assert track.contradicted(Verdict([], ["g"])) == 0
    assert track.contradicted(Verdict([(5, "h")], ["i", "j"])) == 0  # two mislabelled?
    assert track.contradicted(Verdict([(5, "h")], ["i", "j", "k"])) == 1
    quiet = Track(np.eye(4), [(0, "a")], 0.99, 3.0, config)
    for k, verdict in enumerate([Verdict([], ["x"]), Verdict([], ["y"]), Verdict([], ["z"])]):
        assert quiet.contradicted(verdict) == (3 if k == 2 else 0)


def walk_frames(building: ObjectMap, seed: int, **config):
    walk = LongWalk(building, WalkConfig(points_per_object=0, **config), seed=seed)
    return list(walk)


def run_walk(building: ObjectMap, frames, coverage: bool = False, **settings):
    localizer = Localizer(building, local_up=[0, 0, 1], **settings)
    answers = []
    for frame in frames:
        looked = {"coverage": frame.coverage} if coverage else {}
        result = localizer.update(frame.objects, position=frame.T_odom_robot, **looked)
        at = None
        if result.pose is not None:
            p = frame.T_odom_robot[:3, 3]
            at = result.pose[:3, :3] @ p + result.pose[:3, 3]
        error = np.inf if at is None else float(np.linalg.norm(at - frame.robot_global))
        answers.append((result.status, error, result))
    return answers


@pytest.fixture(scope="module")
def building() -> ObjectMap:
    return layout(160, seed=5)


@settings(max_examples=4, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    translation=st.floats(0.0, 0.02),
    yaw_walk=st.floats(0.0, 0.3),
    yaw_bias=st.floats(-0.1, 0.1),
    seed=st.integers(0, 50),
)
def test_drift_below_a_bound_keeps_the_pose_right(building, translation, yaw_walk, yaw_bias, seed):
    drift = Drift(translation, yaw_walk, yaw_bias)
    frames = walk_frames(building, seed, keyframes=90, drift=drift)
    answers = run_walk(building, frames)
    localized = [k for k, (status, _, _) in enumerate(answers) if status == "localized"]
    assert localized, "never localized on a 45 m walk"
    after = answers[localized[0] :]
    right = [error < 0.5 for _, error, _ in after]
    assert np.mean(right) >= 0.9
    assert all(error < 0.5 for status, error, _ in after if status == "localized")


@settings(max_examples=4, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    yaw_walk=st.floats(0.0, 0.3),
    moved=st.floats(0.0, 0.05),
    gone=st.floats(0.0, 0.1),
    wrong_labels=st.floats(0.0, 0.03),
    seed=st.integers(0, 50),
)
def test_an_old_map_and_an_erring_detector_below_a_bound_give_no_wrong_claim(
    building, yaw_walk, moved, gone, wrong_labels, seed
):
    """Drift, moved and gone objects and mislabels below a bound: no `localized` answer is
    wrong (with the sensor's coverage passed, as a robot that has it would).  The bound is
    today's: at 7.8 % moved and 1.6 % mislabels (walk seed 18) a search claims a place 19 m
    off at confidence 0.855 (issue 59: the confidence is not yet calibrated on old maps)."""
    frames = walk_frames(building, seed, keyframes=90, drift=Drift(0.01, yaw_walk, 0.05),
                         world=World(moved=moved, gone=gone), wrong_label_rate=wrong_labels,
                         redetections=10)  # fmt: skip
    answers = run_walk(building, frames, coverage=True)
    assert any(status == "localized" for status, _, _ in answers), "never localized"
    assert all(error < 0.5 for status, error, _ in answers if status == "localized")


def test_a_kidnap_never_yields_a_wrong_localized_claim(building):
    frames = walk_frames(building, seed=7, keyframes=110, kidnap_at=60)
    answers = run_walk(building, frames)
    wrong = [k for k, (status, error, _) in enumerate(answers)
             if status == "localized" and error >= 0.5]  # fmt: skip
    assert wrong == []
    assert any(status == "localized" for status, _, _ in answers[:60])
    after = [k for k, (status, _, _) in enumerate(answers[60:]) if status == "localized"]
    assert after and after[0] <= 15  # relocalized within 15 keyframes
    reasons = [result.reason for _, _, result in answers[60:64]]
    assert CONTRADICTED in reasons


def test_a_tracked_answer_says_how_recent_its_evidence_is(building):
    frames = walk_frames(building, seed=3, keyframes=40)
    answers = run_walk(building, frames)
    tracked = [r for status, _, r in answers if status == "localized" and r.support.tracked]
    assert tracked
    support = tracked[-1].support
    assert support.n_pairs >= 3 and support.seen[0] <= support.seen[1] <= 39
    assert 0 <= support.metres <= 20.0 and support.updates_ago >= 0
    assert tracked[-1].to_dict()["support"]["tracked"] is True


def test_a_restored_localizer_answers_as_the_uninterrupted_one_while_tracking(building):
    frames = walk_frames(building, seed=3, keyframes=60)
    one = Localizer(building, local_up=[0, 0, 1])
    for frame in frames[:35]:
        one.update(frame.objects, position=frame.T_odom_robot)
    assert one.tracking
    state = json.loads(json.dumps(one.state()))  # what a service stores
    other = Localizer.restore(building, state, list(one.local_map), local_up=[0, 0, 1])
    for frame in frames[35:]:
        a = one.update(frame.objects, position=frame.T_odom_robot).to_dict()
        b = other.update(frame.objects, position=frame.T_odom_robot).to_dict()
        for document in (a, b):
            document.pop("timing_ms")
            for step in document["steps"]:
                step.pop("ms")
        assert a == b


def test_a_state_that_does_not_fit_its_objects_is_refused(building):
    localizer = Localizer(building, local_up=[0, 0, 1])
    localizer.update([building[0].replace(id="l0")])
    with pytest.raises(ValueError, match="window's objects"):
        Localizer.restore(building, localizer.state(), [], local_up=[0, 0, 1])
    with pytest.raises(ValueError, match="state"):
        Localizer.restore(building, {"version": 99}, [], local_up=[0, 0, 1])


def test_large_objects_may_land_further_from_their_centre():
    sofa = SemanticObject("s", "sofa", [0.0, 0.0, 0.4], size=[2.0, 1.0, 0.8])
    cup = SemanticObject("c", "cup", [3.0, 0.0, 0.4], points=[[3.0, 0.0, 0.4], [3.1, 0.0, 0.4]])
    bare = SemanticObject("b", "cup", [5.0, 0.0, 0.4])
    found = allowances(ObjectMap([sofa, cup, bare]), tolerance=0.6)
    np.testing.assert_allclose(found, [0.6 + 0.25 * np.linalg.norm([2, 1, 0.8]), 0.625, 0.6])


def test_an_update_larger_than_the_window_keeps_its_newest_objects(building):
    localizer = Localizer(building, window={"objects": 8}, local_up=[0, 0, 1])
    objects = [building[k].replace(id=f"l{k}") for k in range(20)]
    result = localizer.update(objects)
    assert [o.id for o in localizer.local_map] == [f"l{k}" for k in range(14, 20)]
    assert result.status in ("localized", "ambiguous", "failed")
    assert set(localizer._sightings.found) == {f"l{k}" for k in range(14, 20)}

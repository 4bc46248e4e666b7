"""Position priors (`semloc.priors`): validation, the candidate gate, outside-prior hypotheses,
the two-copies map, tracking under a prior, and the Localizer / localize API."""

from __future__ import annotations

import math
import re

import numpy as np
import pytest
from helpers import room
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import semloc
from semloc import Localizer, ObjectMap, Prior
from semloc.priors import GATE_SLACK, OUTSIDE_PRIOR, checked_prior
from semloc.results import Result
from semloc.sim.layouts import layout, observe
from semloc.tracking import TrackingConfig
from semloc.transforms import pose_error, yaw_pose

# ------------------------------------------------------------------------------ validation


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"position": [0, 0, 0], "radius": 0}, "radius must be > 0"),
        ({"position": [0, 0, 0], "radius": -1}, "radius must be > 0"),
        ({"position": [0, 0, 0], "radius": math.nan}, "radius must be finite"),
        ({"position": [0, 0, 0], "radius": math.inf}, "radius must be finite"),
        ({"position": [0, 0, 0], "radius": "far"}, "radius must be a number"),
        ({"position": [0, 0, 0], "radius": True}, "radius must be a number"),
        ({"position": [0, 0], "radius": 1}, "position must be [x, y, z]"),
        ({"position": [0, math.nan, 0], "radius": 1}, "position must be finite"),
        ({"position": "here", "radius": 1}, "position must be [x, y, z]"),
        ({"position": [0, 0, 0], "radius": 1, "floor": (2, 1)}, "z_min <= z_max"),
        (
            {"position": [0, 0, 0], "radius": 1, "floor": (0, math.inf)},
            "floor z_max must be finite",
        ),
        (
            {"position": [0, 0, 0], "radius": 1, "floor": (math.nan, 0)},
            "floor z_min must be finite",
        ),
        ({"position": [0, 0, 0], "radius": 1, "floor": (0,)}, "floor must be (z_min, z_max)"),
        ({"position": [0, 0, 0], "radius": 1, "heading_tolerance": 10}, "needs a heading"),
        ({"position": [0, 0, 0], "radius": 1, "heading": 0, "heading_tolerance": 0}, "(0, 180]"),
        ({"position": [0, 0, 0], "radius": 1, "heading": math.nan}, "heading must be finite"),
        (
            {"position": [0, 0, 0], "radius": 1, "heading": 0, "heading_tolerance": math.nan},
            "heading_tolerance must be finite",
        ),
        (
            {"position": [0, 0, 0], "radius": 1, "heading": 0, "heading_tolerance": 180.5},
            "(0, 180]",
        ),
    ],
)
def test_invalid_priors_are_refused_clearly(kwargs, message):
    with pytest.raises(ValueError, match="^prior: .*" + re.escape(message)):
        Prior(**kwargs)


def test_the_bounds_of_a_valid_prior_are_inclusive():
    # a floor band of one height, a tolerance just above 0, and 180 degrees: all valid
    flat = Prior(position=[0, 0, 0], radius=1, floor=(1, 1))
    assert flat.contains(yaw_pose(0.0, [0, 0, 1])) and not flat.contains(yaw_pose(0.0, [0, 0, 1.1]))
    assert (
        Prior(position=[0, 0, 0], radius=1, heading=0, heading_tolerance=0.5).heading_tolerance
        == 0.5
    )
    assert (
        Prior(position=[0, 0, 0], radius=1, heading=0, heading_tolerance=180).heading_tolerance
        == 180
    )
    assert Prior(position=[0, 0, 0], radius=1).heading_tolerance is None


@pytest.mark.parametrize(
    ("data", "message"),
    [
        (
            {"position": [0, 0, 0]},
            "prior: an object with 'position' [x, y, z] and 'radius' is needed",
        ),
        ({"radius": 1}, "prior: an object with 'position' [x, y, z] and 'radius' is needed"),
        (
            ["position", "radius"],
            "prior: an object with 'position' [x, y, z] and 'radius' is needed",
        ),
        (
            {"position": [0, 0, 0], "radius": 1, "size": 2, "colour": 1},
            "prior: unknown field(s) colour, size",
        ),
    ],
)
def test_a_json_prior_needs_its_fields_and_only_them(data, message):
    with pytest.raises(ValueError, match="^" + re.escape(message) + "$"):
        Prior.from_dict(data)


def test_prior_round_trips_through_json_and_is_checked_by_the_api():
    prior = Prior(position=[1, 2, 3], radius=4, floor=(-1, 1), heading=90, heading_tolerance=20)
    assert Prior.from_dict(prior.to_dict()) == prior
    assert Prior(position=[0, 0, 0], radius=1, heading=45).heading_tolerance == 30.0
    with pytest.raises(ValueError, match="unknown field"):
        Prior.from_dict({"position": [0, 0, 0], "radius": 1, "size": 2})
    g = layout(20, seed=1)
    with pytest.raises(TypeError, match="prior must be a semloc.Prior"):
        Localizer(g, prior=[0, 0, 0])
    with pytest.raises(TypeError, match="prior must be a semloc.Prior"):
        semloc.localize(g, g, prior=5.0)


def test_a_prior_is_written_with_float_coordinates_and_its_own_tolerance():
    assert Prior(position=[1, 2, 3], radius=4).to_dict() == {
        "position": [1.0, 2.0, 3.0],
        "radius": 4.0,
    }
    assert all(type(v) is float for v in Prior(position=[1, 2, 3], radius=4).to_dict()["position"])
    written = Prior(position=[0, 0, 0], radius=1, heading=90, heading_tolerance=20).to_dict()
    assert written["heading"] == 90 and written["heading_tolerance"] == 20


def test_a_prior_equals_only_a_prior_of_the_same_fields():
    prior = Prior(position=[0, 0, 0], radius=1)
    assert prior == Prior(position=[0.0, 0.0, 0.0], radius=1.0) and prior != "prior"
    assert prior != Prior(position=[0, 0, 0], radius=2)
    assert len({prior, Prior(position=[0, 0, 0], radius=1)}) == 1


def test_the_api_reads_a_json_prior_and_names_what_it_cannot_read():
    data = {"position": [1, 2, 3], "radius": 4}
    assert checked_prior(data) == Prior(**data) and checked_prior(None) is None
    with pytest.raises(TypeError, match="^prior must be a semloc.Prior, got list$"):
        checked_prior([0, 0, 0])


def test_contains_includes_its_bounds_exactly():
    prior = Prior(position=[1, 0, 0], radius=2, floor=(-0.5, 0.5))
    assert prior.contains(yaw_pose(0.0, [3, 0, 0]))  # exactly at the radius
    assert not prior.contains(yaw_pose(0.0, [3.01, 0, 0]))
    assert prior.contains(yaw_pose(0.0, [1, 0, -0.5])) and prior.contains(
        yaw_pose(0.0, [1, 0, 0.5])
    )
    assert not prior.contains(yaw_pose(0.0, [1, 0, -0.51]))
    assert not prior.contains(yaw_pose(0.0, [1, 0, 0.51]))
    # widened by `metres`: the band's both edges move out
    assert prior.contains(yaw_pose(0.0, [1, 0, -0.75]), metres=0.25)
    assert prior.contains(yaw_pose(0.0, [1, 0, 0.75]), metres=0.25)
    assert not prior.contains(yaw_pose(0.0, [1, 0, -0.8]), metres=0.25)


def test_the_heading_is_kept_exactly_at_its_tolerance_across_the_wrap():
    # yaw 180 against a heading of -90: 90 degrees off, the long way round is 270
    assert Prior(position=[0, 0, 0], radius=1, heading=-90, heading_tolerance=90).contains(
        yaw_pose(np.pi, [0, 0, 0])
    )
    tight = Prior(position=[0, 0, 0], radius=1, heading=-90, heading_tolerance=89.5)
    assert not tight.contains(yaw_pose(np.pi, [0, 0, 0]))  # by default no extra degrees
    assert tight.contains(yaw_pose(np.pi, [0, 0, 0]), degrees=0.5)
    # a heading of 0 along global +x (no y component) is a heading, within any tolerance
    assert Prior(position=[0, 0, 0], radius=1, heading=0, heading_tolerance=1).contains(np.eye(4))


def test_a_pose_whose_local_x_is_vertical_has_no_heading_and_is_outside_a_heading_prior():
    pose = np.eye(4)
    pose[:3, :3] = [[0, 0, -1], [0, 1, 0], [1, 0, 0]]  # local x along global z
    assert not Prior(position=[0, 0, 0], radius=1, heading=0, heading_tolerance=180).contains(pose)
    assert Prior(position=[0, 0, 0], radius=1).contains(pose)


def test_the_reason_of_an_outside_answer_names_the_distance_and_the_prior_s_bounds():
    pose = yaw_pose(0.0, [4, 0, 0])
    plain = Prior(position=[1, 0, 0], radius=2)
    assert plain.why_outside(pose) == (
        f"{OUTSIDE_PRIOR}: its pose puts the local origin 3.00 m from the prior's position "
        "(radius 2 m)"
    )
    full = Prior(position=[1, 0, 0], radius=2, floor=(0, 1), heading=0)
    assert full.why_outside(pose).endswith(
        "3.00 m from the prior's position (radius 2 m, floor band, heading)"
    )


def test_contains_checks_radius_floor_and_heading():
    prior = Prior(position=[0, 0, 0], radius=2, floor=(-0.5, 0.5), heading=90, heading_tolerance=15)
    assert prior.contains(yaw_pose(np.radians(90), [1, 1, 0]))
    assert not prior.contains(yaw_pose(np.radians(90), [2, 1, 0]))  # beyond the radius
    assert not prior.contains(yaw_pose(np.radians(90), [0, 0, 1]))  # above the floor band
    assert not prior.contains(yaw_pose(np.radians(110), [0, 0, 0]))  # off the heading
    assert prior.contains(yaw_pose(np.radians(-265), [0, 0, 0]))  # 95 deg, wrapped
    # an estimate is admitted with the error of a right pose (0.5 m, 15 deg) beyond the bounds
    assert prior.admits(yaw_pose(np.radians(110), [2.3, 0, 0.9]))
    assert not prior.admits(yaw_pose(np.radians(90), [2.6, 0, 0]))


# -------------------------------------------------------------------------------- the gate


def test_gate_keeps_what_the_prior_allows_and_drops_the_far():
    prior = Prior(position=[0, 0, 0], radius=2)
    global_xyz = np.array([[0.0, 0, 0], [6.9, 0, 0], [7.1, 0, 0], [20, 0, 0]])
    keep = prior.gate(np.array([0.0, 4.0, 0.0]), global_xyz, np.full(4, 1.0))
    assert keep.tolist() == [True, True, False, False]  # reach 2 + 4 + 1 m
    at_reach = prior.gate(np.array([0.0, 4.0, 0.0]), np.array([[7.0, 0, 0]]), np.ones(1))
    assert at_reach.tolist() == [True]  # exactly at the reach: kept


def test_the_floor_band_s_gate_widens_by_the_local_distance_and_the_slack():
    # a local object 2 m from the local origin may be a map object up to 2 m + slack (0.5 m)
    # below or above the band (0, 1): z in [-2.5, 3.5]; the radius still holds
    prior = Prior(position=[0, 0, 0], radius=10, floor=(0, 1))
    z = [-2.5, -2.6, 3.5, 3.6, 0.5]
    xyz = np.array([[0.0, 0, h] for h in z] + [[30.0, 0, 0.5]])
    keep = prior.gate(np.array([0.0, 2.0, 0.0]), xyz, np.full(len(xyz), 0.5))
    assert keep.tolist() == [True, False, True, False, True, False]


def test_the_localizers_gate_allows_the_slack_and_a_quarter_of_each_objects_diagonal():
    """A chair seen 4 m from the local origin, under a prior of radius 2 m: a map chair may lie
    2 + 4 m plus `GATE_SLACK` plus a quarter of its diagonal from the prior's centre, no more
    (a partially seen centre is biased by up to that much): at least tracking's tolerance, so
    a detection that would support a place is never gated out."""
    assert TrackingConfig().track_tolerance <= GATE_SLACK
    size = np.array([0.5, 0.5, 1.0])
    reach = 2.0 + 4.0 + GATE_SLACK + 0.25 * float(np.linalg.norm(size))
    chairs = [semloc.SemanticObject(f"c{i}", "chair", [x, 0.0, 0.0], size=size)
              for i, x in enumerate([reach - 0.01, reach + 0.01, 6.0])]  # fmt: skip
    world = ObjectMap(chairs, up=[0, 0, 1])
    localizer = Localizer(world, local_up=[0, 0, 1], prior=Prior(position=[0, 0, 0], radius=2))
    seen = semloc.SemanticObject("l", "chair", [0.0, 4.0, 0.0])
    assert localizer._search.prior_gated(seen, np.arange(3)).tolist() == [0, 2]


@pytest.fixture(scope="module")
def building() -> ObjectMap:
    return layout(80, seed=11)


@settings(max_examples=25, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(
    seed=st.integers(0, 10_000),
    offset=st.tuples(st.floats(-1, 1), st.floats(-1, 1), st.floats(-1, 1)),
    radius=st.floats(0.5, 6.0),
)
def test_a_true_prior_keeps_a_right_answer_and_never_loses_it(building, seed, offset, radius):
    obs = observe(building, 6, seed=seed)
    truth = obs.T_global_local
    # a prior that holds: the true origin lies within `radius` of its position
    position = truth[:3, 3] + np.asarray(offset) / max(np.linalg.norm(offset), 1.0) * 0.9 * radius
    prior = Prior(position=position, radius=radius)
    base = semloc.localize(building, obs.local_map)
    narrowed = semloc.localize(building, obs.local_map, prior=prior)
    assert all(h.outside_prior is None for h in base.hypotheses)
    assert all(isinstance(h.outside_prior, bool) for h in narrowed.hypotheses)

    def right(result: Result) -> bool:
        if result.pose is None:
            return False
        rotation, translation = pose_error(result.pose, truth)
        return rotation < 15 and translation < 0.5

    if base.status == "localized" and right(base):  # the same answer, as sure
        assert narrowed.status == "localized"
        assert sorted(narrowed.hypotheses[0].pairs) == sorted(base.hypotheses[0].pairs)
        np.testing.assert_allclose(narrowed.pose, base.pose, atol=1e-6)
    if right(base):  # ... or better: a right best place stays right
        assert right(narrowed)
    if narrowed.status == "localized":  # never a wrong place, never outside the prior
        assert right(narrowed)
        assert prior.admits(narrowed.pose)


# ------------------------------------------------------------------ two copies of one room
SHIFT = np.array([30.0, 0.0, 0.0])
TRUE_POSE = yaw_pose(0.7, [0.5, 0.5, 0.0])  # the local origin in copy A, near its corner


@pytest.fixture(scope="module")
def two_rooms() -> tuple[ObjectMap, ObjectMap]:
    """A map holding two identical copies of one room 30 m apart, and a view of copy A."""
    a = room(10)
    b = [o.replace(id=o.id.replace("a", "b"), position=o.position + SHIFT) for o in a]
    world = ObjectMap([*a, *b], up=[0, 0, 1], name="two rooms")
    inverse = np.linalg.inv(TRUE_POSE)
    view = [a[i].transformed(inverse).replace(id=f"l{k}", seen=k) for k, i in enumerate(range(7))]
    return world, ObjectMap(view, up=[0, 0, 1], name="view of A")


def test_two_copies_without_a_prior_are_ambiguous(two_rooms):
    world, view = two_rooms
    result = semloc.localize(world, view)
    assert result.status == "ambiguous"
    assert all(h.outside_prior is None for h in result.hypotheses)
    assert "outside_prior" not in result.to_dict()["hypotheses"][0]  # no prior: JSON unchanged


def test_two_copies_with_a_prior_around_the_true_copy_localize_there(two_rooms):
    world, view = two_rooms
    prior = Prior(position=TRUE_POSE[:3, 3] + [0.8, -0.5, 0.2], radius=1.5)
    result = semloc.localize(world, view, prior=prior)
    assert result.status == "localized", result.reason
    np.testing.assert_allclose(result.pose, TRUE_POSE, atol=1e-6)
    assert all(g.startswith("a") for g, _ in result.hypotheses[0].pairs)
    assert result.hypotheses[0].outside_prior is False
    assert result.to_dict()["hypotheses"][0]["outside_prior"] is False


@pytest.mark.parametrize(
    "prior",
    [
        Prior(position=[34.0, 4.0, 0.5], radius=2.0),  # the wrong room's middle
        Prior(position=[33.0, 3.0, 0.5], radius=3.0),  # nearer, still not the copy's origin
        Prior(position=[30.5, 0.5, 0.0], radius=1.0, floor=(1.0, 2.0)),  # the copy, a floor up
        Prior(position=[30.5, 0.5, 0.0], radius=1.0, heading=-90.0, heading_tolerance=20),
    ],
)
def test_a_prior_around_the_wrong_copy_never_localizes_there(two_rooms, prior):
    world, view = two_rooms
    result = semloc.localize(world, view, prior=prior)
    assert result.status != "localized"
    wrong = TRUE_POSE.copy()
    wrong[:3, 3] += SHIFT
    if result.hypotheses and result.hypotheses[0].pose is not None:
        best = result.hypotheses[0]
        assert best.outside_prior is True
        assert result.reason.startswith(OUTSIDE_PRIOR)
        assert result.pose_is_answer is False
    for h in result.hypotheses:  # kept and marked, not dropped
        if h.pose is not None and not prior.admits(h.pose):
            assert h.outside_prior is True
    assert Result.from_dict(result.to_dict()).hypotheses[0].outside_prior == (
        result.hypotheses[0].outside_prior
    )
    assert any(pose_error(h.pose, wrong)[1] < 0.1 for h in result.hypotheses if h.pose is not None)


def test_a_prior_far_from_both_copies_leaves_no_candidates(two_rooms):
    world, view = two_rooms
    result = semloc.localize(world, view, prior=Prior(position=[15.0, 0.5, 0.0], radius=1.0))
    assert result.status == "failed" and not result.hypotheses
    assert result.reason.startswith("too few candidates within the prior")


def test_the_gate_narrows_the_candidates_in_a_large_map(two_rooms):
    world, view = two_rooms
    free = Localizer(world, local_up=[0, 0, 1])
    near = Localizer(world, local_up=[0, 0, 1], prior=Prior(position=[0.5, 0.5, 0], radius=1))
    free.add(list(view))
    near.add(list(view))
    assert near.n_sets < free.n_sets
    gated = [near._search.gated(o, near._sightings.found[o.id][1]) for o in view]
    assert all(world[int(g)].id.startswith("a") for found in gated for g in found)
    assert sum(map(len, gated)) < sum(len(free._sightings.found[o.id][1]) for o in view)


# ------------------------------------------------------------------ set_prior and tracking


def test_set_prior_applies_next_update_and_ends_a_tracked_claim_outside_it(two_rooms):
    world, view = two_rooms
    objects = list(view)
    localizer = Localizer(world, local_up=[0, 0, 1])
    localizer.set_prior(Prior(position=[0.5, 0.5, 0], radius=1.0))
    first = localizer.update(objects[:5])
    assert first.status == "localized" and localizer.tracking
    # the caller now says the robot is in copy B: the tracked place in A is let go
    localizer.set_prior(Prior(position=[34.0, 4.0, 0.5], radius=2.0))
    assert not localizer.tracking
    moved = localizer.update(objects[5:])
    assert moved.status != "localized"
    assert moved.reason.startswith(OUTSIDE_PRIOR)
    localizer.set_prior(None)  # removed: both copies again
    assert localizer.prior is None
    assert localizer.update([]).status == "ambiguous"


def test_a_tracked_pose_that_leaves_the_prior_ends_the_claim(two_rooms, monkeypatch):
    world, view = two_rooms
    objects = list(view)
    prior = Prior(position=[0.5, 0.5, 0], radius=1.0)
    localizer = Localizer(world, local_up=[0, 0, 1], prior=prior)
    assert localizer.update(objects[:5]).status == "localized" and localizer.tracking
    # the followed pose drifts out of the prior (as a wrong odometry would carry it)
    monkeypatch.setattr(Prior, "admits", lambda self, pose: False)
    result = localizer.update(objects[5:])
    assert not localizer.tracking
    assert result.status == "ambiguous"

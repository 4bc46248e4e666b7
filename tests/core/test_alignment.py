"""Map-to-map alignment (semloc.align): the transform, every correspondence, the merged map,
the pose-graph edge, and a second map that shares nothing."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import T_A_B, benchmark_script, room, second_session
from hypothesis import given, settings
from hypothesis import strategies as st

import semloc
from semloc.alignment import (
    AlignmentConfig,
    _Aligner,
    place_scores,
    pose_information,
    seed_views,
)
from semloc.eval.success import is_success
from semloc.io.g2o import edge_line, parse_edge
from semloc.io.importers.replica import load_replica
from semloc.localizer import Localizer
from semloc.maps import ObjectMap, SemanticObject
from semloc.results import Hypothesis
from semloc.sim.layouts import layout
from semloc.tools.merge import merged_map
from semloc.transforms import pose_error, yaw_pose


@pytest.mark.parametrize("n", [12, 40])  # one update with every object; seed views and growth
def test_two_sessions_of_one_room_give_the_transform_and_every_correspondence(n):
    a = room(n)
    b = second_session(a)
    result = semloc.align(a, b)
    assert result.status == "localized" and result.reason == ""
    rotation, translation = pose_error(result.pose, T_A_B)
    assert rotation < 1e-6 and translation < 1e-6
    assert sorted(result.hypotheses[0].pairs) == sorted((o.id, o.id.replace("a", "b")) for o in a)


def test_a_partial_overlap_matches_only_the_shared_objects():
    a = room(50)
    b_objects = list(second_session(a, slice(20, 50)))
    rng = np.random.default_rng(0)
    extra = [SemanticObject(f"new{i}", "bed", rng.uniform(-30, -20, 3)) for i in range(5)]
    b = ObjectMap([*b_objects, *extra], up=[0, 0, 1], name="B")
    result = semloc.align(a, b, alignment=AlignmentConfig(whole_below=10))
    assert result.status == "localized"
    assert pose_error(result.pose, T_A_B)[1] < 1e-6
    assert sorted(result.hypotheses[0].pairs) == sorted((f"a{i}", f"b{i}") for i in range(20, 50))


def test_a_second_map_that_shares_nothing_fails_with_a_reason():
    a = room(30)
    others = [o.replace(label=f"other-{o.label}") for o in second_session(a)]
    result = semloc.align(a, ObjectMap(others, up=[0, 0, 1]))
    assert result.status == "failed" and result.pose is None
    assert "view" in result.reason or "candidates" in result.reason


def twin_rooms(seen: int, jitter: float, seed: int = 5) -> tuple[ObjectMap, ObjectMap]:
    """A: the first `seen` objects of a 20-object room (its session saw no more) and a twin
    of the whole room 12 m away, each twin object `jitter` m off sideways; B: the whole room."""
    base = room(20)
    rng = np.random.default_rng(seed)
    twins = []
    for o in base:
        angle = rng.uniform(-np.pi, np.pi)
        step = [12.0 + jitter * np.cos(angle), jitter * np.sin(angle), 0.0]
        twins.append(o.transformed(yaw_pose(0.0, step)).replace(id=f"t{o.id}"))
    return ObjectMap([*list(base)[:seen], *twins], up=[0, 0, 1], name="A"), second_session(base)


@pytest.mark.parametrize("whole_below", [24, 5])
def test_a_twin_room_that_pairs_more_objects_a_few_decimetres_off_does_not_win(whole_below):
    # the twin pairs all 20 objects of B, 0.25 m off; the room itself only the 16 A saw
    a, b = twin_rooms(16, 0.25)
    result = semloc.align(a, b, alignment=AlignmentConfig(whole_below=whole_below))
    assert result.status == "localized"
    rotation, translation = pose_error(result.pose, T_A_B)
    assert rotation < 1e-6 and translation < 1e-6
    assert sorted(result.hypotheses[0].pairs) == sorted((f"a{i}", f"b{i}") for i in range(16))


@pytest.mark.parametrize("whole_below", [24, 5])
def test_two_identical_rooms_are_ambiguous(whole_below):
    a, b = twin_rooms(20, 0.0)
    result = semloc.align(a, b, alignment=AlignmentConfig(whole_below=whole_below))
    assert result.status == "ambiguous" and "rival" in result.reason
    twin = T_A_B.copy()
    twin[0, 3] += 12.0
    places = [h.pose for h in result.hypotheses[:2]]
    assert any(pose_error(p, T_A_B)[1] < 1e-6 for p in places)
    assert any(pose_error(p, twin)[1] < 1e-6 for p in places)


def noisy_session(a: ObjectMap, seed: int = 0) -> ObjectMap:
    """B of `a` with every centre 0.1-0.3 m off sideways."""
    rng = np.random.default_rng(seed)
    objects = []
    for o in second_session(a):
        angle, length = rng.uniform(-np.pi, np.pi), rng.uniform(0.1, 0.3)
        step = [length * np.cos(angle), length * np.sin(angle), 0.0]
        objects.append(o.transformed(yaw_pose(0.0, step)))
    return ObjectMap(objects, up=[0, 0, 1], name="B")


@pytest.mark.parametrize("whole_below", [60, 10])
def test_a_noisy_second_map_is_still_aligned_with_every_pair(whole_below):
    a = room(40)
    result = semloc.align(a, noisy_session(a), alignment=AlignmentConfig(whole_below=whole_below))
    assert result.status == "localized"
    rotation, translation = pose_error(result.pose, T_A_B)
    assert rotation < 1.0 and translation < 0.2
    assert sorted(result.hypotheses[0].pairs) == sorted((o.id, o.id.replace("a", "b")) for o in a)


def test_one_moved_object_among_exact_ones_barely_turns_the_pose():
    a = room(10)
    objects = list(second_session(a))
    objects[0] = objects[0].transformed(yaw_pose(0.0, [0.55, 0.0, 0.0]))  # still paired
    result = semloc.align(a, ObjectMap(objects, up=[0, 0, 1]))
    rotation, translation = pose_error(result.pose, T_A_B)
    assert rotation < 0.15 and translation < 0.03  # a plain least-squares fit: 1.5° / 0.28 m


def test_a_small_second_map_gets_the_localizers_answer_with_its_pairs_completed():
    a = room(30)
    b = noisy_session(ObjectMap(list(a)[:12], up=[0, 0, 1]), seed=2)
    result = semloc.align(a, b)
    own = Localizer(a, local_up=b.up).update(list(b))
    assert result.status == own.status and result.confidence == own.confidence
    np.testing.assert_array_equal(result.pose, own.pose)
    assert set(own.hypotheses[0].pairs) <= set(result.hypotheses[0].pairs)
    assert sorted(result.hypotheses[0].pairs) == sorted((f"a{i}", f"b{i}") for i in range(12))


@pytest.mark.parametrize(("seed", "variant"), [(182, "clean"), (283, "moved")])
def test_a_precise_small_second_map_finds_the_room_a_similar_one_outnumbers(seed, variant):
    # bench_align's building of similar rooms: A saw 7-8 of B's 15 objects, a similar room
    # pairs more of them a decimetre or two off; the Localizer alone ranks that room first
    # (and, for the moved case, says `localized` there)
    bench = benchmark_script("bench_align")
    full = layout(400, seed=5, points_per_object=64)
    case = bench.second_session(full, 15, variant, np.random.default_rng(seed))
    result = semloc.align(case.first, case.second)
    assert result.status == "localized" and is_success(result.pose, case.truth)
    assert sorted(result.hypotheses[0].pairs) == sorted(case.pairs)


def test_growth_from_the_right_pose_keeps_it_among_close_objects_of_one_kind(real_sample):
    # Replica office4: B's objects that A lacks lie among A's chairs and wall plugs; a wide
    # pass pairs them crosswise and turned the pose by 34 degrees
    full = load_replica(real_sample("replica", "office4"))
    case = benchmark_script("bench_align").second_session(
        full, 15, "clean", np.random.default_rng(103)
    )
    aligner = _Aligner(case.first, case.second, None, AlignmentConfig(), {})
    place = aligner._grown(Hypothesis(rank=0, score=0.0, pairs=[], pose=case.truth, method="x"))
    rotation, translation = pose_error(place.pose, case.truth)
    assert rotation < 2.0 and translation < 0.1
    assert case.pairs <= set(place.pairs)


def test_place_scores_count_the_agreeing_pairs_of_each_pose():
    a, b = twin_rooms(16, 0.15)
    twin = T_A_B.copy()
    twin[0, 3] += 12.0
    truth, at_twin, nowhere = place_scores(a, b, [T_A_B, twin, yaw_pose(0.0, [100, 0, 0])])
    assert truth == pytest.approx(16.0)  # the 16 objects A saw, exactly
    assert 12.0 < at_twin < 16.0  # all 20 objects, each 0.15 m off (0.75 each), refitted
    assert nowhere == 0.0


def test_views_beyond_the_rare_ones_spread_by_farthest_points():
    xyz = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [10, 0, 0], [20, 0, 0]])
    rarity = np.array([5, 1, 0, 3, 4])  # the rarest is index 2
    centres = [view[0] for view in seed_views(xyz, 3, 1, rarity, rare=1)]
    assert centres == [2, 4, 3]  # then the farthest from it, then the farthest from both
    all_rare = [view[0] for view in seed_views(xyz, 3, 1, rarity)]
    assert all_rare == [2, 3, 4]  # by rarity, at least 3 m apart


def test_the_merged_map_has_each_object_once_with_its_provenance():
    a = room(30)
    b = ObjectMap(
        [*second_session(a, slice(10, 30)), SemanticObject("a3", "bed", [50.0, 50.0, 0.5])],
        up=[0, 0, 1],
    )  # "a3" in B is another object than A's a3
    result = semloc.align(a, b)
    merged = merged_map(a, b.transformed(result.pose), result.hypotheses[0].pairs)
    provenance = {o.id: o.extra["provenance"] for o in merged}
    assert len(merged) == 30 + 1
    assert provenance["a15"] == {"from": "both", "ids": ["a15", "b15"]}
    assert provenance["a2"] == {"from": "A", "ids": ["a2"]}
    assert provenance["B:a3"] == {"from": "B", "ids": ["a3"]}
    np.testing.assert_allclose(merged.get("a15").position, a.get("a15").position, atol=1e-9)
    np.testing.assert_allclose(
        merged.get("B:a3").position, T_A_B[:3, :3] @ [50, 50, 0.5] + T_A_B[:3, 3]
    )


def test_fused_points_are_united_and_the_centre_re_estimated():
    a = ObjectMap([SemanticObject("x", "chair", points=np.zeros((4, 3)))])
    b = ObjectMap([SemanticObject("y", "chair", points=np.ones((4, 3)))])
    fused = merged_map(a, b, [("x", "y")]).get("x")
    assert len(fused.points) == 8
    np.testing.assert_allclose(fused.position, [0.5, 0.5, 0.5])


def test_the_g2o_edge_parses_back_to_the_transform_and_its_information():
    a = room(20)
    b = second_session(a)
    pose = semloc.align(a, b).pose
    local, glob = b.positions, a.positions
    information = pose_information(pose, local, glob)
    id_a, id_b, parsed, parsed_information = parse_edge(edge_line(pose, information, 3, 7))
    assert (id_a, id_b) == (3, 7)
    np.testing.assert_allclose(parsed, pose, atol=1e-7)
    scale = np.array([1, 1, 1, 2, 2, 2.0])
    np.testing.assert_allclose(parsed_information, information * np.outer(scale, scale), rtol=1e-7)
    with pytest.raises(ValueError):
        parse_edge("VERTEX_SE3:QUAT 0 0 0 0 0 0 0 1")


def test_the_information_grows_with_the_pairs_and_is_symmetric_positive_definite():
    a = room(20)
    few = pose_information(np.eye(4), a.positions[:5], a.positions[:5])
    many = pose_information(np.eye(4), a.positions, a.positions)
    assert np.allclose(many, many.T) and np.linalg.eigvalsh(many).min() > 0
    assert np.all(np.diag(many) > np.diag(few))


@settings(max_examples=40)
@given(
    n=st.integers(1, 60),
    views=st.integers(1, 10),
    size=st.integers(3, 15),
    seed=st.integers(0, 1000),
)
def test_seed_views_are_neighbourhoods_of_distinct_centres(n, views, size, seed):
    xyz = np.random.default_rng(seed).uniform(-10, 10, (n, 3))
    found = seed_views(xyz, views, size)
    assert len(found) == min(views, n)
    for view in found:
        assert len(view) == min(size, n) and len(set(view.tolist())) == len(view)
        outside = np.setdiff1d(np.arange(n), view)
        # some member is the centre: no point outside the view is nearer to it than a member
        assert any(
            len(outside) == 0
            or np.linalg.norm(xyz[view] - xyz[c], axis=1).max()
            <= np.linalg.norm(xyz[outside] - xyz[c], axis=1).min()
            for c in view
        )


def _mutual_nearest_literal(R, t, radius, cand_a, cand_b, cand_a_xyz, cand_b_xyz):
    """Guided matching as the rules say it: per object of B its nearest candidate within the
    radius (ties: the earlier candidate), kept when no other B object's choice of the same A
    object is nearer (ties: the lower B index); rows ascending by A index."""
    d2 = np.sum((cand_b_xyz @ R.T + t - cand_a_xyz) ** 2, axis=1)
    choice = {}
    for c in range(len(cand_a)):
        b = int(cand_b[c])
        if d2[c] < radius * radius and (b not in choice or d2[c] < d2[choice[b]]):
            choice[b] = c
    keep = {}
    for b in sorted(choice):
        a = int(cand_a[choice[b]])
        if a not in keep or d2[choice[b]] < d2[keep[a]]:
            keep[a] = choice[b]
    return sorted((a, int(cand_b[c])) for a, c in keep.items())


@settings(max_examples=80)
@given(
    seed=st.integers(0, 2**31),
    n_a=st.integers(1, 12),
    n_b=st.integers(1, 12),
    radius=st.floats(0.05, 3.0),
    lattice=st.booleans(),
)
def test_mutual_nearest_follows_the_matching_rules(seed, n_a, n_b, radius, lattice):
    """The compiled guided matching pairs exactly as the literal rules do, ties included
    (lattice positions make equal distances common)."""
    from semloc._alignment_fast import mutual_nearest

    rng = np.random.default_rng(seed)
    a_xyz = rng.integers(0, 4, (n_a, 3)).astype(float) if lattice else rng.uniform(0, 4, (n_a, 3))
    b_xyz = rng.integers(0, 4, (n_b, 3)).astype(float) if lattice else rng.uniform(0, 4, (n_b, 3))
    allowed = rng.random((n_b, n_a)) < 0.6
    cand_b, cand_a = np.nonzero(allowed)  # grouped by B, ascending: as `_Aligner` gathers them
    R, t = (
        (np.eye(3), np.zeros(3))
        if lattice
        else (yaw_pose(rng.uniform(-3, 3))[:3, :3], rng.normal(size=3) * 0.3)
    )
    found = mutual_nearest(R, t, radius, cand_a, cand_b, a_xyz[cand_a], b_xyz[cand_b], n_a, n_b)
    literal = _mutual_nearest_literal(R, t, radius, cand_a, cand_b, a_xyz[cand_a], b_xyz[cand_b])
    assert [tuple(p) for p in found.tolist()] == literal

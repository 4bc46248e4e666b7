"""Place retrieval (`semloc.places`): the true place is always kept, identical copies are all
kept, small maps are untouched, a view that fits too many places waits, the index is shared."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import room
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import semloc
from semloc import Localizer, ObjectMap
from semloc.clustering import MergeCriterion
from semloc.localizer import LocalizerConfig
from semloc.maps import SemanticObject
from semloc.places import PlaceIndex, RetrievalConfig, place_index
from semloc.sim.longwalk import tiled
from semloc.transforms import pose_error, yaw_pose

RETRIEVE_ALL = LocalizerConfig(retrieval={"above": 0})  # retrieval on any map


def _view(world: ObjectMap, indices, pose: np.ndarray, noise: float, seed: int) -> ObjectMap:
    rng = np.random.default_rng(seed)
    inverse = np.linalg.inv(pose)
    objects = []
    for k, i in enumerate(indices):
        obj = world[int(i)].transformed(inverse)
        objects.append(obj.replace(id=f"l{k}", position=obj.position + rng.normal(0, noise, 3),
                                   seen=k))  # fmt: skip
    return ObjectMap(objects, up=[0, 0, 1], name="view")


@settings(max_examples=25, suppress_health_check=[HealthCheck.too_slow])
@given(
    seed=st.integers(0, 10_000),
    size=st.integers(2, 9),
    noise=st.floats(0.0, 0.1),
    yaw=st.floats(-np.pi, np.pi),
)
def test_the_true_candidates_are_always_retrieved(seed, size, noise, yaw):
    """The support of a cell bounds from above how many local objects a candidate in it is
    consistent with, so no cell beats the true place and the true candidates are kept."""
    world = tiled(room(24, seed=seed % 7), 3, 2, keep=0.8, seed=seed)
    rng = np.random.default_rng(seed)
    centre = world.positions[rng.integers(len(world))]
    near = np.argsort(np.linalg.norm(world.positions - centre, axis=1))[:size]
    pose = yaw_pose(yaw, centre + rng.normal(0, 2, 3))
    view = _view(world, near, pose, noise, seed)
    index = PlaceIndex(world, RetrievalConfig(above=0))
    localizer = Localizer(world, RETRIEVE_ALL)
    found = [localizer._context.candidates.candidates(o) for o in view]
    cfg = localizer.config.clustering
    support = index.support(view.positions, found, MergeCriterion.of(cfg))
    for true, kept in zip(near, index.kept(support, found)):
        assert true in kept


def test_small_maps_are_not_retrieved_and_answer_as_before():
    world = tiled(room(20), 2, 2, seed=1)
    view = _view(world, range(6), yaw_pose(0.4, [1.0, 2.0, 0.0]), 0.0, 0)
    assert Localizer(world)._context.places is None  # below `above` (3000 objects)
    plain = semloc.localize(world, view, config=LocalizerConfig(retrieval={"above": None}))
    default = semloc.localize(world, view)
    assert plain.status == default.status == "localized"
    np.testing.assert_array_equal(plain.pose, default.pose)
    assert [h.pairs for h in plain.hypotheses] == [h.pairs for h in default.hypotheses]
    assert [s.top_scores for s in plain.steps] == [s.top_scores for s in default.steps]


def test_identical_copies_are_all_kept_and_stay_ambiguous():
    a = room(12)
    shift = np.array([40.0, 0.0, 0.0])
    b = [o.replace(id=o.id.replace("a", "b"), position=o.position + shift) for o in a]
    world = ObjectMap([*a, *b], up=[0, 0, 1], name="two copies")
    view = _view(world, range(6), yaw_pose(0.3, [0.5, 0.5, 0.0]), 0.0, 0)
    result = semloc.localize(world, view, config=RETRIEVE_ALL)
    assert result.status == "ambiguous"
    wrong = yaw_pose(0.3, [0.5, 0.5, 0.0])
    wrong[:3, 3] += shift
    poses = [h.pose for h in result.hypotheses if h.pose is not None]
    assert any(pose_error(p, yaw_pose(0.3, [0.5, 0.5, 0.0]))[1] < 0.05 for p in poses)
    assert any(pose_error(p, wrong)[1] < 0.05 for p in poses)


def test_retrieval_finds_the_one_room_that_holds_the_view():
    world = tiled(room(30, seed=5), 6, 6, keep=0.7, seed=2)  # 36 alike, not identical, rooms
    truth = yaw_pose(1.1, world.positions[500] + [0.3, -0.2, 0.0])
    near = np.argsort(np.linalg.norm(world.positions - world.positions[500], axis=1))[:8]
    view = _view(world, near, truth, 0.02, 3)
    with_retrieval = semloc.localize(world, view, config=RETRIEVE_ALL)
    best = with_retrieval.hypotheses[0]  # (copies that kept the same objects may rival it)
    rotation, translation = pose_error(best.pose, truth)
    assert rotation < 1.0 and translation < 0.1
    localizer = Localizer(world, RETRIEVE_ALL, local_up=[0, 0, 1])
    localizer.update(list(view))
    kept = sum(len(k) for k in localizer._search.retrieved.values())
    every = sum(len(localizer._sightings.found[o.id][1]) for o in view)
    assert kept < 0.7 * every  # the clustering saw a part of the candidates


def test_a_view_that_fits_too_many_places_waits_with_a_reason():
    chairs = [
        SemanticObject(f"c{i}", "chair", [x, y, 0.5])
        for i, (x, y) in enumerate((x, y) for x in range(60) for y in range(60))
    ]
    world = ObjectMap(chairs, up=[0, 0, 1], name="a hall of chairs")
    view = ObjectMap(
        [SemanticObject("l0", "chair", [0, 0, 0.5], seen=0),
         SemanticObject("l1", "chair", [1, 0, 0.5], seen=1)], up=[0, 0, 1], name="two chairs",
    )  # fmt: skip
    result = semloc.localize(world, view, config=LocalizerConfig(retrieval={"above": 0}))
    assert result.status == "failed"
    assert result.reason.startswith("the view so far fits too many places of the map")


def test_the_index_is_built_once_per_map_and_anew_for_a_changed_map():
    world = tiled(room(20), 2, 2, seed=1)
    config = RetrievalConfig(above=0)
    index = place_index(world, config)
    assert place_index(world, config) is index
    assert place_index(world, config.model_copy(update={"slack": 0.5})) is index  # query-time
    changed = world.with_objects(list(world)[:-1])
    assert place_index(changed, config) is not index
    assert index.nbytes > 0 and len(index.words) == len(index.cells)
    assert np.all(np.diff(index.words) >= 0)


@pytest.mark.parametrize("n", [0, 1])
def test_tiny_maps_build_an_empty_index(n):
    world = ObjectMap([SemanticObject("a", "chair", [0, 0, 0])][:n], up=[0, 0, 1], name="tiny")
    index = PlaceIndex(world, RetrievalConfig(above=0))
    assert len(index.words) == 0


def test_places_follow_the_rooms_objects_are_in():
    a = SemanticObject("a", "chair", [0.5, 0.5, 0.5], extra={"room": "R(1)"})
    b = SemanticObject("b", "table", [1.0, 0.5, 0.5], extra={"room": "R(2)"})  # through a wall
    c = SemanticObject("c", "lamp", [1.5, 0.5, 0.5])  # no room
    d = SemanticObject("d", "sofa", [1.2, 0.8, 0.5], extra={"room": "R(1)"})
    index = PlaceIndex(ObjectMap([a, b, c, d], up=[0, 0, 1], name="rooms"), RetrievalConfig())
    assert index.n_cells == 3  # one 4 m cell, cut by the rooms
    assert index.cell_of[0] == index.cell_of[3] != index.cell_of[1] != index.cell_of[2]


def _spread(n: int = 5) -> PlaceIndex:
    """n chairs in n cells, cell k holding chair k."""
    chairs = [SemanticObject(f"c{k}", "chair", [4.0 * k + 0.5, 0.5, 0.5]) for k in range(n)]
    index = PlaceIndex(ObjectMap(chairs, up=[0, 0, 1], name="cells"), RetrievalConfig())
    assert index.cell_of.tolist() == list(range(n))
    return index


@pytest.mark.parametrize(
    ("support", "kept"),
    [
        ([8, 6, 5, 1, 0], [0, 1]),  # a quarter of 8 is 2: down to 6
        ([6, 5, 4, 1, 0], [0, 1]),  # a quarter of 6 is 1 (rounded down): down to 5
        ([3, 2, 1, 0, 0], [0, 1]),  # at least one fewer
        ([1, 1, 0, 0, 0], [0, 1]),  # never a cell that supports nothing
        ([0, 0, 0, 0, 0], [0, 1, 2, 3, 4]),  # no cell supports it: every candidate
    ],
)
def test_a_candidate_is_kept_when_its_cell_is_within_the_slack_of_the_best(support, kept):
    index = _spread()
    found = np.arange(5)
    assert index.kept(np.array([support]), [found])[0].tolist() == kept


def test_a_local_object_with_more_kept_candidates_than_wait_above_waits():
    index = _spread()
    index.config = RetrievalConfig(wait_above=2)
    support = np.array([[3, 3, 0, 0, 0], [3, 3, 3, 0, 0]])
    kept = index.kept(support, [np.arange(5), np.arange(5)])
    assert [k.tolist() for k in kept] == [[0, 1], []]


def _pair_support(local_gap: float, map_gap: float) -> int:
    """The support of the one cell for a local chair with a table `local_gap` from it, when
    the map's chair and table are `map_gap` apart (gamma 1, tolerance 0.5 m: a slack of
    0.5 m; reach 6 m, bins of 0.5 m)."""
    objects = [SemanticObject("c", "chair", [0.1, 0.1, 0.1]),
               SemanticObject("t", "table", [0.1 + map_gap, 0.1, 0.1])]  # fmt: skip
    config = RetrievalConfig(cell=20.0)
    index = PlaceIndex(ObjectMap(objects, up=[0, 0, 1], name="pair"), config)
    local_xyz = np.array([[0.0, 0, 0], [local_gap, 0, 0]])
    support = index.support(local_xyz, [np.array([0]), np.array([1])], MergeCriterion(1.0, 0.5))
    return int(support[0].max())


def test_a_local_pair_is_looked_up_only_when_every_consistent_map_distance_is_indexed():
    """A pair 5.5 m apart with a slack of 0.5 m reaches 6 m, the index's reach: looked up;
    5.6 m apart it could match a map pair beyond the reach, which the index does not hold."""
    assert _pair_support(5.5, 5.5) == 1
    assert _pair_support(5.6, 5.6) == 0


def test_a_local_pair_looks_up_every_bin_within_its_slack():
    """3.4 m apart with a slack of 0.5 m: the bins of 2.9 m to 3.9 m (bins 5 to 7)."""
    assert _pair_support(3.4, 2.95) == 1 and _pair_support(3.4, 3.85) == 1
    assert _pair_support(3.4, 2.45) == 0 and _pair_support(3.4, 4.05) == 0

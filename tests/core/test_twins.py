"""Twins (`semloc.twins`): the map's own copies of a place, found from the map alone, and the
Localizer weighing a copy its search did not list before it claims."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from semloc import Localizer, LocalizerConfig, ObjectMap, SemanticObject
from semloc.transforms import yaw_pose
from semloc.twins import (
    NEAREST,
    TwinIndex,
    YawMotions,
    _anchor_pairs,
    _motions,
    _placed,
    copy_holds,
    copy_leads,
    label_codes,
    twin_lead,
    twin_pairs,
    twins,
)

UP = np.array([0.0, 0.0, 1.0])
ROOM = [  # (label, x, y, z): a room whose labels are all different
    ("sofa", 0.0, 0.0, 0.4), ("table", 2.0, 0.5, 0.4), ("lamp", 3.5, 2.5, 1.2),
    ("fridge", -1.0, 3.0, 0.9), ("tv", 1.0, 4.0, 1.0), ("plant", 4.0, -1.0, 0.5),
]  # fmt: skip


def building(copies: list[np.ndarray], drop: dict[int, set[str]] | None = None) -> ObjectMap:
    """The room at the origin and moved by each of `copies`, copy i without `drop[i]`."""
    objects = []
    for i, S in enumerate([np.eye(4), *copies]):
        for label, *xyz in ROOM:
            if label in (drop or {}).get(i, set()):
                continue
            p = S[:3, :3] @ np.array(xyz) + S[:3, 3]
            objects.append(SemanticObject(id=f"{label}-{i}", label=label, position=p))
    return ObjectMap(objects, up=UP)


def find(m: ObjectMap, members, **kw) -> list[np.ndarray]:
    return twins(m.positions, label_codes(m.labels), UP, np.array(members), 0.3, **kw)


def test_a_room_with_one_copy_has_one_twin_the_copys_motion():
    S = yaw_pose(np.pi / 2, [30.0, 5.0, 0.0])
    m = building([S])
    found = find(m, range(len(ROOM)))
    assert len(found) == 1
    np.testing.assert_allclose(found[0], S, atol=1e-9)


def test_a_room_alone_has_no_twin():
    assert find(building([]), range(len(ROOM))) == []


def test_a_copy_needs_the_min_share_of_the_objects():
    S = yaw_pose(np.pi, [20.0, 0.0, 0.0])
    three_kept = building([S], {1: {"sofa", "lamp", "tv"}})  # 3 of 6 left: half
    assert len(find(three_kept, range(len(ROOM)))) == 1
    assert find(three_kept, range(len(ROOM)), min_share=0.6) == []
    two_kept = building([S], {1: {"sofa", "lamp", "tv", "plant"}})  # 2 of 6: fixes no pose
    assert find(two_kept, range(len(ROOM)), min_share=0.0) == []


def test_twins_are_listed_most_objects_placed_first_each_once():
    near, far = yaw_pose(0.3, [15.0, 0.0, 0.0]), yaw_pose(-1.0, [0.0, 40.0, 0.0])
    m = building([near, far], {1: {"plant"}})  # the near copy lost one object
    found = find(m, range(len(ROOM)))
    assert len(found) == 2
    np.testing.assert_allclose(found[0], far, atol=1e-9)
    np.testing.assert_allclose(found[1], near, atol=1e-9)


def test_twin_pairs_move_each_pair_onto_the_copy_one_to_one():
    S = yaw_pose(np.pi / 2, [30.0, 5.0, 0.0])
    m = building([S], {1: {"lamp"}})
    pairs = [(i, 10 + i) for i in range(len(ROOM))]
    moved = twin_pairs(S, pairs, m.positions, label_codes(m.labels), 0.3, cKDTree(m.positions))
    names = [(str(m.ids[g]), l) for g, l in moved]
    assert names == [
        (f"{label}-1", 10 + i) for i, (label, *_) in enumerate(ROOM) if label != "lamp"
    ]


@given(
    yaw=st.floats(-np.pi, np.pi),
    x=st.floats(8.0, 200.0),
    y=st.floats(-200.0, 200.0),
    z=st.floats(-3.0, 3.0),
)
@settings(max_examples=40)
def test_any_upright_copy_is_found_with_its_motion(yaw, x, y, z):
    S = yaw_pose(yaw, [x, y, z])
    found = find(building([S]), range(len(ROOM)))
    assert len(found) == 1
    np.testing.assert_allclose(found[0], S, atol=1e-6)


def test_a_copy_the_search_did_not_list_is_weighed_before_a_claim():
    # two identical rooms; a search that reports one place (top_k=1) would claim it alone
    m = building([yaw_pose(np.pi / 2, [30.0, 5.0, 0.0])])
    T = yaw_pose(0.4, [1.0, 0.5, 0.0])
    local = [SemanticObject(id=f"l-{label}", label=label,
                            position=np.linalg.solve(T, [*xyz, 1.0])[:3])
             for label, *xyz in ROOM]  # fmt: skip
    r = Localizer(m, LocalizerConfig(top_k=1), local_up=UP).update(local)
    assert r.status == "ambiguous" and "rank 2" in r.reason  # (weighed, listed within top_k)
    assert len(r.hypotheses) == 1


def _localized_in(m: ObjectMap) -> str:
    T = yaw_pose(0.4, [1.0, 0.5, 0.0])
    local = [SemanticObject(id=f"l-{label}", label=label,
                            position=np.linalg.solve(T, [*xyz, 1.0])[:3])
             for label, *xyz in ROOM]  # fmt: skip
    r = Localizer(m, LocalizerConfig(top_k=1), local_up=UP).update(local)
    if r.status == "localized":
        assert {g.rsplit("-", 1)[1] for g, _ in r.hypotheses[0].pairs} == {"0"}
    return r.status


def test_a_copy_lacking_two_of_the_views_objects_is_told_apart_one_is_not():
    S = yaw_pose(np.pi / 2, [30.0, 5.0, 0.0])
    assert _localized_in(building([S], {1: {"lamp", "tv"}})) == "localized"
    assert _localized_in(building([S], {1: {"lamp"}})) == "ambiguous"


def test_told_apart_needs_two_objects_the_copy_lacks_and_none_it_adds():
    from semloc.decision import TWIN_APART, told_apart
    from semloc.results import Hypothesis

    def place(locals_: str) -> Hypothesis:
        return Hypothesis(rank=1, score=1.0, pairs=[(f"g{l}", l) for l in locals_], pose=None)

    assert TWIN_APART == 2
    assert told_apart(place("abcde"), place("abc"))
    assert not told_apart(place("abcde"), place("abcd"))  # one object: a gone object's share
    assert not told_apart(place("abcde"), place("abcf"))  # the copy pairs one the place lacks
    assert not told_apart(place("abc"), place("abcde"))


# twin_lead: the evidence of the latest updates for a copy against the tracked place --------
@pytest.mark.parametrize(
    ("updates", "lead"),
    [
        ([[["+local a", "+local b"]]], (2, 1, 0)),
        ([[["+local a"]], [["+local a"]]], (1, 1, 0)),  # a re-detection is the same object
        ([[["-map x"]], [["+map x"]]], (1, 1, 0)),  # seen, then missing: its newest evidence
        ([[["+map x"]], [["-map x"]]], (0, 0, 0)),  # missing, then seen at its place
        ([[["+local a"]], None, [["+local b"]]], (2, 3, 0)),  # an update not weighed
        ([[["+local a", "+local b", "-map y"]]], (1, 1, 0)),
    ],
)
def test_twin_lead_counts_each_object_once_by_its_newest_evidence(updates, lead):
    assert twin_lead(updates) == lead


def test_twin_lead_weighs_only_the_updates_since_the_robot_was_carried_off():
    """Three objects for the place before, two for the copy since: the copy leads by two over
    the newest two updates (the older ones are the place the robot left)."""
    before = [["-map x", "-map y", "-map z"]]
    since = [[["+local a"]], [["+local b"]]]
    assert twin_lead([before, *since]) == (2, 2, 0)
    assert twin_lead([before, [["+local a", "-map w"]]]) == (0, 0, 0)


def test_twin_lead_takes_the_best_copy():
    updates = [[["+local a"], ["+local a", "+local b", "+map x"]]]
    assert twin_lead(updates) == (3, 1, 1)
    assert twin_lead([[["+local a"], []], [[], ["+local b"]]]) == (1, 1, 1)  # the fewest updates
    assert twin_lead([]) == (0, 0, 0) and twin_lead([None]) == (0, 0, 0)


def test_twin_lead_takes_the_best_copy_wherever_it_is_listed():
    assert twin_lead([[["+local a", "+local b"], ["+local a"]]]) == (2, 1, 0)
    assert twin_lead([[["+local a"], ["+local a", "+local b"], []]]) == (2, 1, 1)


def test_copy_leads_lists_each_copys_lead_and_none_without_copies():
    """Per copy of the newest update: its lead and over how many updates; a copy the place
    leads, or one nothing tells apart, leads by nothing over no update."""
    updates = [[["+local a"], ["-map x"], []], [["+local b"], ["+map y"], []]]
    assert copy_leads(updates) == [(2, 2), (1, 1), (0, 0)]
    assert copy_leads([[["-map x"]]]) == [(0, 0)]
    assert copy_leads([]) == [] and copy_leads([None]) == []
    assert copy_leads([[["+local a"]], None]) == []  # the newest update weighs no copy


@pytest.mark.parametrize(("kinds", "x", "held"), [([0], 0.5, True), ([0], 0.51, False),
                                                  ([1], 0.0, False), ([1, 0], 0.0, True)])  # fmt: skip
def test_copy_holds_a_map_object_of_the_kinds_within_its_allowance(kinds, x, held):
    """The copy S moves the map by 10 m along x; a chair (kind 0) stands at 10 m."""
    positions = np.array([[0.0, 0, 0], [10.0, 0, 0], [30.0, 0, 0]])
    codes, allowance = np.array([0, 0, 1]), np.array([0.5, 0.5, 0.5])
    S = np.eye(4)
    S[0, 3] = 10.0
    at = np.array([x, 0.0, 0.0])
    found = copy_holds(S, at, np.array(kinds), positions, codes, allowance, cKDTree(positions))
    assert found is held


def test_copy_holds_weighs_each_map_object_by_its_own_gap():
    """Two chairs 0.4 m either side of where the copy puts the point, each within its own
    allowance (0.5 m): the copy holds a chair there."""
    positions = np.array([[0.0, 0, 0], [9.6, 0, 0], [10.4, 0, 0]])
    codes, allowance = np.array([0, 0, 0]), np.full(3, 0.5)
    S = np.eye(4)
    S[0, 3] = 10.0
    tree = cKDTree(positions)
    assert copy_holds(S, np.zeros(3), np.array([0]), positions, codes, allowance, tree)


def test_twin_pairs_take_the_nearest_object_of_the_label_each_once():
    """A pair moved to (10, 0, 0) takes the nearer of two chairs within the tolerance (the
    one 0.1 m off, not the one 0.15 m off listed first); a second pair moved there finds it
    taken and takes the other chair; with one chair, it takes none."""
    positions = np.array([[0.0, 0, 0], [9.85, 0, 0], [10.0, 0.1, 0], [0.05, 0, 0]])
    codes = np.zeros(4, dtype=np.int64)
    S = yaw_pose(0.0, [10.0, 0.0, 0.0])
    tree = cKDTree(positions)
    assert twin_pairs(S, [(0, 7)], positions, codes, 0.3, tree) == [(2, 7)]
    assert twin_pairs(S, [(0, 7), (3, 8)], positions, codes, 0.3, tree) == [(2, 7), (1, 8)]
    one = positions[[0, 2]], codes[:2], cKDTree(positions[[0, 2]])
    assert twin_pairs(S, [(0, 7), (0, 8)], *one[:2], 0.3, one[2]) == [(1, 7)]


@pytest.mark.parametrize(
    ("b2", "kept"),
    [((9.75, 0), True), ((9.7, 0), False), ((10.0, 0.25), True), ((10.0, 0.3), False)],
)
def test_an_anchor_pair_matches_map_pairs_at_its_distance_and_height_within_the_tolerance(b2, kept):
    """The anchor pair (a, b) lies 2 m apart along x at one height; a map pair of the same
    labels (a at 8 m) matches it when its distance and its height difference are each within
    0.25 m of the anchor pair's (1.75 m apart, or 0.25 m higher, exactly: kept)."""
    positions = np.array([[0.0, 0, 0], [2.0, 0, 0], [8.0, 0, 0], [b2[0], 0, b2[1]]])
    codes = np.array([0, 1, 0, 1], dtype=np.int64)
    motions = _motions(positions, codes, UP, 0, 1, 0.25, TwinIndex(positions, codes)).matrices()
    moves = sorted(round(float(S[0, 3]), 6) for S in motions)
    assert moves == ([0.0, 8.0] if kept else [0.0])


def test_anchor_pairs_take_the_rarest_labels_each_with_its_rarest_farthest_partner():
    """Members 0 (label A) and 1 (B) are rarer than 2, 3, 4 (C): 0 pairs with 1, its rarest
    partner beyond `SPAN` across up; 1 with the farthest unused C (4, 4 m off); 2 with the
    only one left, 0.8 m across (nearer than `SPAN`: the farthest there is; 5 m above it does
    not count); 3 and 4 find no unused member."""
    place = [[0.0, 0, 0], [3.0, 0, 0], [1.0, 0, 0], [1.8, 0, 5], [-1.0, 0, 0]]
    positions = np.array(place + [[100 + x, y, z] for x, y, z in place])
    codes = np.array([0, 1, 2, 2, 2] * 2)
    assert _anchor_pairs(positions, codes, np.arange(5), UP, 5) == [(0, 1), (1, 4), (2, 3)]


def test_an_anchor_without_a_partner_is_passed_over_and_the_next_ones_are_tried():
    """Members 0 (label A) and 1 (B) are the rarest, 2 and 3 (C) commoner.  Member 0 pairs
    with 2, the only one at least `SPAN` across from it; member 1 then finds no unused partner
    but 3, right above it (nothing across); member 2 still pairs, with 1."""
    place = [[0.0, 0, 0], [1.0, 0, 0], [5.0, 0, 0], [1.0, 0, 3]]
    others = [[100.0, 0, 0], [101.0, 0, 0], [105.0, 0, 0]]  # one more A, B and C elsewhere
    positions = np.array(place + others)
    codes = np.array([0, 1, 2, 2, 0, 1, 2])
    assert _anchor_pairs(positions, codes, np.arange(4), UP, 3) == [(0, 2), (2, 1)]


def test_no_motion_places_nothing():
    positions = np.array([[0.0, 0, 0], [1.0, 0, 0], [2.0, 0, 0]])
    codes = np.zeros(3, dtype=np.int64)
    none = YawMotions(positions[0], positions[1], np.zeros((0, 3)), np.zeros((0, 3)), UP)
    placed = _placed(none, positions, codes, np.arange(3), 0.3, TwinIndex(positions, codes))
    assert placed.shape == (0,) and placed.dtype.kind == "i"


def test_a_copy_found_by_one_anchor_pair_is_kept_whatever_the_next_pairs_find():
    """The place above, its copy 100 m off without member 3: the pairs (0, 1) and (1, 4) find
    the copy, the last pair (2, 3) only the place itself."""
    place = [[0.0, 0, 0], [3.0, 0, 0], [1.0, 0, 0], [1.8, 0, 5], [-1.0, 0, 0]]
    copy = [[100 + x, y, z] for k, (x, y, z) in enumerate(place) if k != 3]
    positions = np.array(place + copy)
    codes = np.array([0, 1, 2, 2, 2, 0, 1, 2, 2])
    found = twins(positions, codes, UP, np.arange(5), 0.3)
    assert len(found) == 1
    np.testing.assert_allclose(found[0], yaw_pose(0.0, [100.0, 0.0, 0.0]), atol=1e-9)


@pytest.mark.parametrize(("anchors", "found"), [(2, 0), (3, 1)])
def test_only_the_given_number_of_anchor_pairs_is_tried(anchors, found):
    """The place above; its copy 100 m off holds every label, but its table (member 1) stands
    1.5 m off its place: the pairs (0, 1) and (1, 4) do not match there, the third pair
    (2, 3) does.  Two anchor pairs miss the copy, three find it."""
    place = [[0.0, 0, 0], [3.0, 0, 0], [1.0, 0, 0], [1.8, 0, 5], [-1.0, 0, 0]]
    copy = [[100 + x, y + (1.5 if k == 1 else 0.0), z] for k, (x, y, z) in enumerate(place)]
    positions = np.array(place + copy)
    codes = np.array([0, 1, 2, 2, 2] * 2)
    assert len(twins(positions, codes, UP, np.arange(5), 0.3, anchors=anchors)) == found


def test_anchors_of_equally_rare_labels_follow_the_members_order():
    """Sixteen members of sixteen labels, the odd ones held twice by the map, the even ones
    three times: the anchors are the first odd members, in the members' order (a stable sort:
    the same anchors, and the same twins, on every machine)."""
    grid = np.array([[1.5 * (i % 4), 1.5 * (i // 4), 0.0] for i in range(16)])
    extra = [i for i in range(16) for _ in range(1 if i % 2 else 2)]
    positions = np.vstack([grid, grid[extra] + [100.0, 0.0, 0.0]])
    codes = np.concatenate([np.arange(16), extra])
    pairs = _anchor_pairs(positions, codes, np.arange(16), UP, 3)
    assert [a for a, _ in pairs] == [1, 3, 5]


class _CountingTree(cKDTree):
    """A k-d tree that counts its nearest-neighbour queries."""

    queries = 0

    def query(self, *args, **kwargs):
        self.queries += 1
        return super().query(*args, **kwargs)


def test_the_twins_search_queries_the_tree_it_is_given():
    """A caller's tree of the map's positions is used, not built again (the map's tree is
    built once per map), for what the grid cannot tell: here half the copy's objects have
    `NEAREST` objects of another label at their very spot (which are the nearest?)."""
    m = building([yaw_pose(np.pi / 2, [30.0, 5.0, 0.0])])
    crowded = np.repeat(np.arange(len(ROOM), len(ROOM) + 3), NEAREST)
    positions = np.vstack([m.positions, m.positions[crowded]])
    codes = np.concatenate([label_codes(m.labels), np.full(len(crowded), 99)])
    tree = _CountingTree(positions)
    found = twins(positions, codes, UP, np.arange(len(ROOM)), 0.3, tree=tree)
    assert len(found) == 1 and tree.queries > 0


def _placed_plainly(S, positions, codes, members, tolerance):
    """`_placed`'s count by a KD-tree query of every member of every motion."""
    moved = np.einsum("mij,kj->mki", S[:, :3, :3], positions[members]) + S[:, None, :3, 3]
    gaps, near = cKDTree(positions).query(
        moved.reshape(-1, 3), k=NEAREST, distance_upper_bound=tolerance
    )
    labels = np.where(np.isfinite(gaps), codes[np.minimum(near, len(codes) - 1)], -1)
    hit = (labels == np.tile(codes[members], len(S))[:, None]).any(axis=1)
    return hit.reshape(len(S), len(members)).sum(axis=1)


@settings(max_examples=60)
@given(st.integers(0, 2**32 - 1), st.integers(0, 6), st.sampled_from([0.2, 0.5, 1.0]))
def test_the_grids_count_of_placed_members_is_the_kd_trees(seed, need, tolerance):
    """Crowded maps of few labels (often more than `NEAREST` objects within the tolerance),
    some objects doubled at the same spot under another label (equally near objects), motions
    onto the map's own objects and anywhere: the compiled count (`_twins_fast`) is the
    KD-tree's wherever it reaches `need`, and under `need` wherever the KD-tree's is."""
    rng = np.random.default_rng(seed)
    positions = rng.uniform(0.0, [6.0, 4.0, 2.0], size=(int(rng.integers(5, 80)), 3))
    doubled = rng.choice(len(positions), size=len(positions) // 4)
    positions = np.vstack([positions, positions[doubled]])
    codes = rng.integers(0, 3, size=len(positions))
    members = rng.choice(len(positions), size=int(rng.integers(1, 9)), replace=False)
    onto = positions[rng.integers(0, len(positions), size=40)]
    onto[20:] += rng.normal(0.0, 1.0, (20, 3))
    yaws = np.concatenate([np.zeros(20), rng.uniform(-np.pi, np.pi, 20)])
    turned = np.column_stack([np.cos(yaws), np.sin(yaws), np.zeros(40)])
    S = YawMotions(positions[members[0]], np.array([1.0, 0, 0]), onto, turned, UP)
    plain = _placed_plainly(S.matrices(), positions, codes, members, tolerance)
    fast = _placed(S, positions, codes, members, tolerance, TwinIndex(positions, codes), need)
    reached = plain >= need
    np.testing.assert_array_equal(fast[reached], plain[reached])
    assert (fast[~reached] < need).all()


def _turned_building(up: np.ndarray, S: np.ndarray) -> tuple[ObjectMap, np.ndarray]:
    """`ROOM`, its objects each at another height, and its copy moved by `S` about z; both
    turned so that z becomes `up`: the map and the copy's motion in it."""
    e3 = up / np.linalg.norm(up)
    e1 = np.cross(e3, [1.0, 0.0, 0.0]) if abs(e3[0]) < 0.9 else np.cross(e3, [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    Q = np.eye(4)
    Q[:3, :3] = np.column_stack([e1, np.cross(e3, e1), e3])
    objects = []
    for i, T in enumerate([np.eye(4), S]):
        for k, (label, x, y, _) in enumerate(ROOM):
            p = Q @ T @ np.array([x, y, 0.3 * k, 1.0])
            objects.append(SemanticObject(id=f"{label}-{i}", label=label, position=p[:3]))
    return ObjectMap(objects, up=e3), Q @ S @ Q.T


@pytest.mark.parametrize("up", [(0.0, 0.0, 1.0), (0.0, 2.0, 0.0), (1.0, 2.0, 2.0)])
def test_a_copy_is_found_about_any_up_axis_of_any_length(up):
    """Objects at different heights (every anchor pair has a height difference), the map's up
    along z, y or tilted, given at any length: the copy's motion about it is found."""
    up = np.array(up)
    m, S = _turned_building(up, yaw_pose(np.pi / 3, [25.0, -10.0, 0.0]))
    found = twins(m.positions, label_codes(m.labels), up, np.arange(len(ROOM)), 0.3)
    assert len(found) == 1
    np.testing.assert_allclose(found[0], S, atol=1e-9)


def test_a_place_of_three_objects_has_twins():
    S = yaw_pose(0.5, [30.0, 0.0, 0.0])
    assert len(find(building([S]), range(3))) == 1


SQUARE = [("sofa", 0.0, 0.0), ("table", 2.0, 0.5), ("lamp", 3.5, 2.5), ("tv", 2.5, 3.0)]
"""A place whose centroid (2, 1.5) and copies' moves are exact in binary."""


def _square_copies(shifts: list[float]) -> ObjectMap:
    objects = [SemanticObject(f"{label}-{i}", label, [x + dx, y, 0.5])
               for i, dx in enumerate([0.0, *shifts]) for label, x, y in SQUARE]  # fmt: skip
    return ObjectMap(objects, up=UP)


@pytest.mark.parametrize(("shifts", "found"), [([4.0], [4.0]), ([3.75], []), ([8.0, 12.0], [8.0, 12.0])])  # fmt: skip
def test_twins_lie_at_least_apart_from_the_place_and_from_each_other(shifts, found):
    """A copy 4 m off (`apart`) is a twin, one 3.75 m off is the place's own repetition; two
    copies 4 m from each other are two twins."""
    m = _square_copies(shifts)
    moves = twins(m.positions, label_codes(m.labels), UP, np.arange(len(SQUARE)), 0.25)
    assert sorted(float(S[0, 3]) for S in moves) == found


def test_at_most_eight_twins_are_listed():
    copies = [yaw_pose(0.0, [20.0 * k, 0.0, 0.0]) for k in range(1, 10)]
    assert len(find(building(copies), range(len(ROOM)))) == 8

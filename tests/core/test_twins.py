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
from semloc.twins import copy_holds, label_codes, twin_lead, twin_pairs, twins

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
@settings(max_examples=40, deadline=None)
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
        ([[["+local a", "+local b"]]], (2, 1)),
        ([[["+local a"]], [["+local a"]]], (1, 1)),  # a re-detection is the same object
        ([[["-map x"]], [["+map x"]]], (1, 1)),  # seen, then missing: its newest evidence
        ([[["+map x"]], [["-map x"]]], (0, 0)),  # missing, then seen at its place
        ([[["+local a"]], None, [["+local b"]]], (2, 3)),  # an update not weighed
        ([[["+local a", "+local b", "-map y"]]], (1, 1)),
    ],
)
def test_twin_lead_counts_each_object_once_by_its_newest_evidence(updates, lead):
    assert twin_lead(updates) == lead


def test_twin_lead_weighs_only_the_updates_since_the_robot_was_carried_off():
    """Three objects for the place before, two for the copy since: the copy leads by two over
    the newest two updates (the older ones are the place the robot left)."""
    before = [["-map x", "-map y", "-map z"]]
    since = [[["+local a"]], [["+local b"]]]
    assert twin_lead([before, *since]) == (2, 2)
    assert twin_lead([before, [["+local a", "-map w"]]]) == (0, 0)


def test_twin_lead_takes_the_best_copy():
    updates = [[["+local a"], ["+local a", "+local b", "+map x"]]]
    assert twin_lead(updates) == (3, 1)
    assert twin_lead([]) == (0, 0) and twin_lead([None]) == (0, 0)


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

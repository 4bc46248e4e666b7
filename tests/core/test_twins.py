"""Twins (`semloc.twins`): the map's own copies of a place, found from the map alone, and the
Localizer weighing a copy its search did not list before it claims."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.spatial import cKDTree

from semloc import Localizer, LocalizerConfig, ObjectMap, SemanticObject
from semloc.transforms import yaw_pose
from semloc.twins import label_codes, twin_pairs, twins

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

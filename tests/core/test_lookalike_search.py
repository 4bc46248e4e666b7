"""The search in a building of look-alike rooms (issue 59): copies of the view's place are not
crowded out of the search, and a search that had to leave out places as well supported as its
best cannot claim (`semloc.decision.cut_search`, `new_regions`)."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import room

import semloc
from semloc import Localizer, LocalizerConfig, ObjectMap, SemanticObject
from semloc.decision import (
    PLACE_APART,
    SEARCH_CUT,
    Decision,
    DecisionConfig,
    as_well_supported,
    cut_search,
    new_regions,
)
from semloc.transforms import yaw_pose

TRUTH = yaw_pose(0.4, [1.0, 0.5, 0.0])


# --- the rules -------------------------------------------------------------------------------
def test_a_cut_search_cannot_claim():
    cut = cut_search(Decision("localized", ""), True, 8)
    assert cut.status == "ambiguous" and cut.reason.startswith(SEARCH_CUT)
    assert "8 pairs" in cut.reason


def test_an_uncut_search_decides_as_before():
    for decision in (Decision("localized", ""), Decision("ambiguous", "a rival"),
                     Decision("failed", "no set")):  # fmt: skip
        assert cut_search(decision, False, 8) == decision


def test_a_cut_ambiguous_answer_says_the_cut_first_and_keeps_its_reason():
    cut = cut_search(Decision("ambiguous", "a rival place within the margin"), True, 5)
    assert cut.status == "ambiguous" and cut.reason.startswith(SEARCH_CUT)
    assert cut.reason.endswith("; a rival place within the margin")


def test_a_failed_answer_stays_failed_when_cut():
    assert cut_search(Decision("failed", "no set"), True, 2) == Decision("failed", "no set")


def test_as_well_supported_is_the_residual_rule_of_the_verdict():
    d = DecisionConfig()
    edge = (1.0 + d.margin) * 0.1 + d.residual_floor
    assert as_well_supported(6, edge, (6, 0.1), d)
    assert not as_well_supported(6, edge + 1e-6, (6, 0.1), d)
    assert not as_well_supported(5, 0.0, (6, 0.1), d)
    assert as_well_supported(7, 0.1, (6, 0.1), d)


def test_new_regions_take_one_set_per_region_beyond_the_first():
    x = [0.0, 0.5, PLACE_APART + 1.5, PLACE_APART + 2.0, -PLACE_APART, 3 * PLACE_APART]
    centroids = np.array([[v, 0.0, 0.0] for v in x])
    # row 1 lies by row 0; row 2 is new; row 3 lies by row 2; row 4 lies exactly `apart`
    # from row 0 (its nearest): not farther, the same region; row 5 is new
    assert new_regions(centroids, 1).tolist() == [2, 5]
    assert new_regions(centroids, 3).tolist() == [5]
    assert new_regions(centroids, 6).tolist() == []


# --- in the Localizer ------------------------------------------------------------------------
def _copies(count: int, apart: float = 40.0, jitter: float = 0.0) -> tuple[ObjectMap, list]:
    """`count` copies of one room, `apart` metres from each other along x; the copies after
    the first have their objects moved by `jitter` metres in random directions."""
    a = list(room(10))
    rng = np.random.default_rng(0)
    objects = [o.replace(id=f"c{c}/{o.id}", position=o.position + [c * apart, 0.0, 0.0]
                         + (jitter * _direction(rng) if c else 0.0))
               for c in range(count) for o in a]  # fmt: skip
    return ObjectMap(objects, up=[0, 0, 1], name=f"{count} copies"), a


def _direction(rng: np.random.Generator) -> np.ndarray:
    angle = rng.uniform(-np.pi, np.pi)
    return np.array([np.cos(angle), np.sin(angle), 0.0])


def _view(a: list) -> ObjectMap:
    inverse = np.linalg.inv(TRUTH)
    objects = [o.transformed(inverse).replace(id=f"l{k}", seen=k) for k, o in enumerate(a[:6])]
    return ObjectMap(objects, up=[0, 0, 1], name="view")


def test_more_identical_places_than_are_listed_cut_the_search():
    """Two identical copies, one hypothesis listed: the other is left out, so no claim (it
    would be a coin toss)."""
    world, a = _copies(2)
    result = semloc.localize(world, _view(a), config=LocalizerConfig(top_k=1))
    assert result.status == "ambiguous" and result.reason.startswith(SEARCH_CUT)


def test_as_many_identical_places_as_are_listed_do_not_cut_the_search():
    world, a = _copies(2)
    result = semloc.localize(world, _view(a), config=LocalizerConfig(top_k=2))
    assert result.status == "ambiguous" and not result.reason.startswith(SEARCH_CUT)


def test_a_left_out_place_that_fits_clearly_worse_does_not_cut_the_search():
    """The copy's objects lie 0.25 m off: as many pairs, but a residual the best beats by the
    margin, so leaving it out loses nothing."""
    world, a = _copies(2, jitter=0.25)
    result = semloc.localize(world, _view(a), config=LocalizerConfig(top_k=1))
    assert not result.reason.startswith(SEARCH_CUT), result.reason


def test_a_unique_place_listed_alone_is_not_cut():
    world, a = _copies(1)
    result = semloc.localize(world, _view(a), config=LocalizerConfig(top_k=1))
    assert result.status == "localized", result.reason


@pytest.mark.parametrize("copies", [2, 3])
def test_in_a_building_every_copy_is_screened_or_the_search_says_it_was_cut(copies):
    """Place retrieval on (a building), one set screened: the copy elsewhere is screened
    too, one set per new region, up to `screened_sets` more; a third copy is one too many."""
    world, a = _copies(copies)
    config = LocalizerConfig(above=0, screened_sets=1)
    result = semloc.localize(world, _view(a), config=config)
    assert result.status == "ambiguous"
    places = {h.pairs[0][0].split("/")[0] for h in result.hypotheses if len(h.pairs) == 6}
    if copies == 2:
        assert places == {"c0", "c1"} and not result.reason.startswith(SEARCH_CUT)
    else:
        assert result.reason.startswith(SEARCH_CUT)


def test_a_small_map_screens_only_its_best_sets_and_its_twins_come_before_a_claim():
    """Without place retrieval (a small map) the screening is as calibrated: `screened_sets`
    sets, no region added, so the sets list one copy; the copy the best place would be
    claimed without comes from the map itself (`semloc.twins`), and the answer is not cut."""
    world, a = _copies(2)
    config = LocalizerConfig(above=None, screened_sets=1)
    result = semloc.localize(world, _view(a), config=config)
    places = [h.pairs[0][0].split("/")[0] for h in result.hypotheses if len(h.pairs) == 6]
    assert sorted(places) == ["c0", "c1"]
    assert result.status == "ambiguous" and not result.reason.startswith(SEARCH_CUT)


def test_new_regions_stop_at_the_most_asked_for():
    centroids = np.array([[k * 2 * PLACE_APART, 0.0, 0.0] for k in range(6)])
    assert new_regions(centroids, 1, most=2).tolist() == [1, 2]
    assert new_regions(centroids, 1).tolist() == [1, 2, 3, 4, 5]


def _table_lamp_and_chairs(copies: int = 12, apart: float = 40.0) -> ObjectMap:
    """`copies` identical rooms of a table, a lamp and 30 chairs in rows."""
    base = [("table", 0.0, 0.0), ("lamp", 2.0, 0.5)]
    base += [("chair", 0.6 * (i % 6), 2.0 + 0.6 * (i // 6)) for i in range(30)]
    objects = [SemanticObject(f"c{c}/o{i}", label, [x + c * apart, y, 0.5])
               for c in range(copies) for i, (label, x, y) in enumerate(base)]  # fmt: skip
    return ObjectMap(objects, up=[0, 0, 1], name="copies")


def test_updates_whose_objects_all_wait_do_not_age_the_sets():
    """The table and the lamp make a set per copy; then chair after chair waits in place
    retrieval (360 candidates in the retrieved places, 20 allowed).  Those updates give the
    sets nothing to merge with, so the copies' sets stay (they would expire after
    `expiry_updates` updates but the `protect_top` best)."""
    config = LocalizerConfig(above=0, wait_above=20, protect_top=1)
    localizer = Localizer(_table_lamp_and_chairs(), config, local_up=[0, 0, 1])
    first = [SemanticObject("l0", "table", [0.0, 0.0, 0.5]),
             SemanticObject("l1", "lamp", [2.0, 0.5, 0.5])]  # fmt: skip
    localizer.add(first)
    sets = localizer.n_sets
    assert sets >= 12  # (one per copy at least)
    for k in range(config.clustering.expiry_updates + 2):
        localizer.add([SemanticObject(f"c{k}", "chair", [0.6 * k, 2.0, 0.5])])
        assert localizer.n_sets == sets

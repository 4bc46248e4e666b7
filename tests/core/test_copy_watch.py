"""A tracked place's copies (`semloc.copy_watch.CopyWatch`): when they are looked up again."""

from __future__ import annotations

import numpy as np
import pytest

from semloc import LocalizerConfig, ObjectMap, SemanticObject
from semloc.copy_watch import CopyWatch
from semloc.map_context import MapContext
from semloc.tracking import Track, TrackingConfig, Verdict

OBJECTS = [SemanticObject(f"g{k}", "chair", [1.5 * k, 0.0, 0.5]) for k in range(12)]


@pytest.fixture
def watched(monkeypatch):
    """A watch over a track whose newest 4 pairs are map objects 0-3, with its copies' lookups
    recorded (none found)."""
    context = MapContext(ObjectMap(OBJECTS, up=[0, 0, 1]), LocalizerConfig(), None)
    looked_up: list[list[int]] = []
    monkeypatch.setattr(context, "copies_of", lambda members, anchors: looked_up.append(
        sorted(members.tolist())) or [])  # fmt: skip
    track = Track(np.eye(4), [(g, f"l{g}") for g in range(4)], 0.9, 1.0, TrackingConfig())
    return CopyWatch(context, track_pairs=4), track, looked_up


AGAINST = Verdict([], ["x"])  # one detection the place cannot explain
SEEN = [SemanticObject("x", "chair", [20.0, 0.0, 0.5])]


@pytest.mark.parametrize("held", [[0, 1, 9, 10], [0, 1, 2, 3]])
def test_the_copies_stand_while_half_the_newest_pairs_or_more_are_theirs(watched, held):
    watch, track, looked_up = watched
    watch.copies = (np.array(held), [])
    assert watch.weigh(5, track, AGAINST, SEEN, {"x": np.array([0])}, np.zeros(0, int)) == (
        0,
        0,
        None,
    )
    assert looked_up == []  # (exactly half held: the robot has not walked on)


def test_the_copies_are_looked_up_again_when_fewer_than_half_are_theirs(watched):
    watch, track, looked_up = watched
    watch.copies = (np.array([0, 9, 10, 11]), [])
    watch.weigh(5, track, AGAINST, SEEN, {"x": np.array([0])}, np.zeros(0, int))
    assert looked_up == [[0, 1, 2, 3]]  # the newest pairs' map objects
    assert watch.copies[0].tolist() == [0, 1, 2, 3]


def test_walking_on_with_nothing_against_the_place_looks_nothing_up(watched):
    watch, track, looked_up = watched
    watch.copies = (np.array([9, 10, 11, 0]), [])
    supported = Verdict([(0, "l0")], [])
    assert watch.weigh(5, track, supported, [], {}, np.zeros(0, int)) == (0, 0, None)
    assert looked_up == []  # (nothing seen tells the rooms apart: no news)

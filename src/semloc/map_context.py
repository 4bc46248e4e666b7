"""What a Localizer derives from its global map once, shared by its search and its track.

The map is fixed for a Localizer's life, so everything read off it alone is computed when
first needed and kept: the candidate index (labels through the taxonomy, the descriptor gate),
place retrieval for large maps (`semloc.places`), a KD-tree of the positions (and one per
label), per object the tolerances tracking and the prior's gate allow and half its footprint
(a detector's split), the labels as integers, and the map's copies of the places lately asked
about (`semloc.twins`).  What depends on the map alone (and a setting) is shared by every
Localizer of one map object while it lives, as its point clouds, candidate similarities and
place index are: a localization on a large map does not rebuild it.  The copies asked about
stay the Localizer's own (which places it asked about is its history).
"""

from __future__ import annotations

import threading
import weakref
from collections.abc import Callable
from functools import cached_property
from typing import Any, TypeVar

import numpy as np
from scipy.spatial import cKDTree

from semloc.association import CandidateIndex, Describer
from semloc.decision import PLACE_APART
from semloc.maps import ObjectMap, SemanticObject
from semloc.places import PlaceIndex, place_index
from semloc.pose import cached_cloud
from semloc.priors import GATE_SLACK
from semloc.settings import LocalizerConfig
from semloc.tracking import allowances, footprints
from semloc.twins import ANCHORS, TwinIndex, label_codes, twins

TWINS_WEIGHED = 4
"""The copies of a place weighed: those that hold most of its objects."""
TWINS_KEPT = 64
"""The twins (`semloc.twins`) of this many latest places are kept, not looked up again."""

_SHARED: weakref.WeakKeyDictionary[ObjectMap, dict[tuple, Any]] = weakref.WeakKeyDictionary()
_SHARED_LOCK = threading.RLock()  # (a service's sessions of one map run in several threads;
# reentrant: one fact may be made from another)
T = TypeVar("T")


def shared(global_map: ObjectMap, key: tuple, make: Callable[[], T]) -> T:
    """What `make()` derives from `global_map` alone (`key` names it), made once per map
    object and shared while the map lives."""
    with _SHARED_LOCK:
        facts = _SHARED.setdefault(global_map, {})
        if key not in facts:
            facts[key] = make()
        return facts[key]


class MapContext:
    """The global map (with its shape descriptors) and what is read off it once."""

    def __init__(
        self, global_map: ObjectMap, config: LocalizerConfig, describer: Describer | None
    ) -> None:
        if not isinstance(global_map, ObjectMap):
            raise TypeError(
                f"Localizer needs an ObjectMap as global map, got {type(global_map).__name__}"
            )
        if describer is not None:
            global_map = global_map.with_objects(describer.describe(global_map))
        self.map = global_map
        self.config = config
        self.describer = describer
        self.descriptor_gate = config.association.gate(describer)
        self.candidates = CandidateIndex(global_map, config.association, self.descriptor_gate)
        above = config.retrieval.above
        self.places: PlaceIndex | None = (
            place_index(global_map, config.retrieval)
            if above is not None and len(global_map) >= above
            else None
        )
        self._twin_motions: dict[tuple[int, ...], list[np.ndarray]] = {}  # (anchors, members)

    def described(self, objects: list[SemanticObject]) -> list[SemanticObject]:
        """Local objects with their shape descriptors (as they are, without a describer)."""
        return objects if self.describer is None else list(self.describer.describe(objects))

    def prepare(self) -> None:
        """Prepare the point cloud of every map object now (downsampled points, normals,
        KD-tree), instead of when a localization first needs it.

        The preparation is kept per map object (`pose.cached_cloud`), so it is done once per
        loaded map whichever Localizer asks: call it after loading a map, before time-critical
        use (about half a millisecond per object of a few hundred points)."""
        for obj in self.map:
            cached_cloud(obj, self.config.pose)

    @cached_property
    def tree(self) -> cKDTree:
        """A KD-tree of the map's positions (looks, twins)."""
        return shared(self.map, ("tree",), lambda: cKDTree(self.map.positions))

    @cached_property
    def diagonals(self) -> np.ndarray:
        """Each map object's box diagonal (NaN without a box)."""
        return self._array(("diagonals",), lambda: np.linalg.norm(self.map.sizes, axis=1))

    @cached_property
    def allowances(self) -> np.ndarray:
        """Per map object, how far from where a pose puts a detection it may lie (tracking)."""
        tolerance = self.config.tracking.track_tolerance
        return self._array(("allowances", tolerance), lambda: allowances(self.map, tolerance))

    @cached_property
    def parts(self) -> np.ndarray:
        """How near (m) to a detection of a map object another one is a part of it (a
        detector's split): half the object's footprint (`tracking.footprints`)."""
        return self._array(("parts",), lambda: 0.5 * footprints(self.map))

    @cached_property
    def gate_slack(self) -> np.ndarray:
        """Per map object, how far its centre may lie from a detection's (the prior's gate)."""
        return self._array(("gate_slack", GATE_SLACK), lambda: allowances(self.map, GATE_SLACK))

    @cached_property
    def codes(self) -> np.ndarray:
        """The map's labels as integers (twins)."""
        return self._array(("codes",), lambda: label_codes(self.map.labels))

    @cached_property
    def twin_index(self) -> TwinIndex:
        """Per label, the map objects of it and their KD-tree (twins)."""
        return shared(self.map, ("twin_index",), lambda: TwinIndex(self.map.positions, self.codes))

    def _array(self, key: tuple, make: Callable[[], np.ndarray]) -> np.ndarray:
        """A shared array (`shared`), read-only: one Localizer must not change another's."""

        def frozen() -> np.ndarray:
            array = make()
            array.flags.writeable = False
            return array

        return shared(self.map, key, frozen)

    def copies_of(self, members: np.ndarray, anchors: int = ANCHORS) -> list[np.ndarray]:
        """The twins of the map objects `members` (`semloc.twins`, through `anchors` anchor
        pairs), kept for the latest `TWINS_KEPT` sets of members: a set that shares most of
        its members with a kept one is the same place (grown by an object or two) and has its
        copies."""
        found = tuple(sorted(members.tolist()))
        key = (anchors, *found)
        for kept in reversed(self._twin_motions):
            same = kept[0] == anchors and len(set(kept[1:]) & set(found))
            if same and same >= 0.75 * max(len(found), len(kept) - 1):
                return self._twin_motions[kept]
        if key not in self._twin_motions:
            if len(self._twin_motions) >= TWINS_KEPT:
                self._twin_motions.pop(next(iter(self._twin_motions)))
            up = self.map.up
            self._twin_motions[key] = [] if up is None else twins(
                self.map.positions, self.codes, up, members,
                self.config.verification.inlier_tolerance, tree=self.tree, apart=PLACE_APART,
                most=TWINS_WEIGHED, anchors=anchors, index=self.twin_index,
            )  # fmt: skip
        return self._twin_motions[key]

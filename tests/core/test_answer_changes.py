"""One rule for the changes of an answer (`semloc.changes.answer_changes`): the Localizer's
own, recomputed from a saved answer's pose and pairs (`update-map --result`, the service's
change reports) it gives the same changes."""

from __future__ import annotations

import numpy as np

import semloc
from semloc.changes import answer_changes
from semloc.localizer import LocalizerConfig
from semloc.maps import ObjectMap, SemanticObject
from semloc.transforms import yaw_pose


def _maps() -> tuple[ObjectMap, ObjectMap]:
    rng = np.random.default_rng(5)
    labels = ["chair", "table", "lamp", "cabinet", "sofa", "plant"]
    objects = [SemanticObject(str(i), labels[i % 6], np.r_[rng.uniform(0, 8, 2), 0.5])
               for i in range(14)]  # fmt: skip
    to_local = np.linalg.inv(yaw_pose(0.4, [1.0, 2.0, 0.0]))
    seen = [
        o.transformed(to_local).replace(id=f"l{o.id}", seen=k) for k, o in enumerate(objects[:8])
    ]
    seen[2] = seen[2].replace(position=seen[2].position + [1.2, 0.0, 0.0])  # moved
    far = to_local[:3, :3] @ [4.0, 9.5, 0.5] + to_local[:3, 3]
    seen.append(SemanticObject("new", "plant", far, seen=8))
    return ObjectMap(objects), ObjectMap(seen)


def test_the_changes_of_a_saved_answer_are_the_localizer_s():
    global_map, local_map = _maps()
    result = semloc.localize(global_map, local_map)
    assert result.status == "localized"
    config = LocalizerConfig()
    again = answer_changes(global_map, list(local_map), result.pose, result.best.pairs,
                           config.association, config.changes)  # fmt: skip
    assert again == result.changes
    assert result.changes.moved or result.changes.new


def test_pairs_naming_unknown_objects_are_left_out():
    global_map, local_map = _maps()
    result = semloc.localize(global_map, local_map)
    padded = [*result.best.pairs, ("no-such-map-object", "l0"), ("0", "no-such-local")]
    assert answer_changes(global_map, list(local_map), result.pose, padded) == result.changes

"""Localization when the detector names objects differently from the map (issue 36).

    SEMLOC_DATA=/path/to/shared/data/real PYTHONPATH=src python benchmarks/vocabulary.py \
        [--views 20] [--buildings 2] [--seed 0] [--markdown TABLE.md]

Cases: the real-layout variants of `semloc.eval.variants` (ScanNet scene0000_00, Replica
office4, 3RScan scene_1, and the Scan2CAD scan map of scene0470_00; skipped without the data) and simulated buildings
(`semloc.sim.layouts.layout`, 150 objects); clean, noisy and dynamic; 3, 5 and 8 observed
objects; `--views` views per cell.  Each case is localized four times:

    map names      the local objects keep the map's labels (the reference);
    detector/exact the local labels renamed into a COCO / LVIS-style detector vocabulary
                   (`DETECTOR`, our own renaming: synonyms, coarser and finer classes,
                   confusable classes, other spellings), labels compared by equality only
                   (`min_similarity=1`: what semloc did before the taxonomy);
    detector       the same names, soft candidates from the shipped taxonomy (the default);
    embeddings     the detector's names, plus synthetic embeddings on both maps: one random
                   prototype per true class, instance noise per object (same-class cosine
                   about 0.8-0.95, other classes about 0.45-0.65).

Printed per source and variant, and per number of objects: top-1, top-10, claims right /
wrong and coverage (share of views `localized` and right), the four conditions side by side.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

from semloc.eval.datasets import real_data_dir
from semloc.eval.variants import (
    OBJECT_COUNTS,
    VARIANTS,
    Case,
    Outcome,
    evaluate,
    make_case,
    variant_maps,
)
from semloc.io.importers.scan2cad import load_scan2cad
from semloc.maps import ObjectMap
from semloc.semantics import taxonomy
from semloc.sim.layouts import layout

DETECTOR = {
    # ScanNet (raw ScanNet / NYU names) -> detector
    "couch": "sofa", "tv": "television set", "refrigerator": "fridge", "trashcan": "trash_can",
    "table": "dining table", "pillow": "cushion", "cabinet": "cupboard", "nightstand": "night_stand",
    "counter": "countertop", "window": "windows", "curtain": "curtains", "shower": "shower stall",
    "bookshelf": "bookcase", "scale": "bathroom scale", "clock": "wall clock", "towel": "bath towel",
    "dishrack": "dish drainer",
    "microwave": "microwave oven", "tissue box": "tissues", "backpack": "rucksack",
    "stool": "chair", "toaster oven": "oven", "laundry basket": "basket",  # COCO-coarse
    # Replica
    "lamp": "light", "wall-plug": "power outlet", "anonymize_picture": "picture frame",
    "bin": "wastebasket", "anonymize_text": "sign", "panel": "board", "tv-screen": "tv",
    "vent": "air vent", "chair": "chairs",
    # 3RScan (NYU40 catch-alls: a detector names the thing generically)
    "otherprop": "object", "otherfurniture": "furniture", "otherstructure": "structure",
    "box": "cardboard box",
    # simulated buildings
    "sofa": "couch", "plant": "potted plant", "shelf": "shelves", "fridge": "refrigerator",
    "whiteboard": "white board", "monitor": "computer monitor",
}  # fmt: skip
"""Map label -> the name a COCO / LVIS-style detector gives it (ours; unlisted: unchanged)."""

CONDITIONS = ("map names", "detector/exact", "detector", "embeddings")
DIMENSION, SHARED, INSTANCE_NOISE = 256, 0.6, 0.42


def rename(local: ObjectMap) -> ObjectMap:
    """The local objects with the detector's names."""
    return local.with_objects(o.replace(label=DETECTOR.get(o.label, o.label)) for o in local)


class Embedder:
    """Synthetic embeddings: a prototype per true class, instance noise per object."""

    def __init__(self, seed: int) -> None:
        self._rng = np.random.default_rng(seed)
        self._shared = _unit(self._rng.normal(size=DIMENSION))
        self._prototypes: dict[str, np.ndarray] = {}

    def prototype(self, label: str) -> np.ndarray:
        name = taxonomy().resolve(label) or label
        if name not in self._prototypes:
            own = _unit(self._rng.normal(size=DIMENSION))
            self._prototypes[name] = _unit(
                np.sqrt(SHARED) * self._shared + np.sqrt(1 - SHARED) * own
            )
        return self._prototypes[name]

    def embed(self, objects: ObjectMap, true_labels: dict[str, str]) -> ObjectMap:
        """`objects` with an embedding each, drawn around the prototype of its true class."""
        out = []
        for o in objects:
            noise = _unit(self._rng.normal(size=DIMENSION)) * INSTANCE_NOISE
            out.append(o.replace(embedding=self.prototype(true_labels.get(o.id, o.label)) + noise))
        return objects.with_objects(out)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def conditions(case: Case, embedder: Embedder) -> dict[str, tuple[Case, dict]]:
    """The four versions of a case, each with its Localizer settings."""
    detected = rename(case.local)
    truth = {o.id: o.label for o in case.local}
    embedded = Case(embedder.embed(case.prior, {}), embedder.embed(detected, truth), case.truth)
    return {
        "map names": (case, {}),
        "detector/exact": (Case(case.prior, detected, case.truth), {"min_similarity": 1.0}),
        "detector": (Case(case.prior, detected, case.truth), {}),
        "embeddings": (embedded, {}),
    }


def sources(buildings: int) -> dict[str, ObjectMap]:
    maps: dict[str, ObjectMap] = {}
    data = real_data_dir()
    if data is not None:
        maps.update(variant_maps(data))
        maps["Scan2CAD"] = load_scan2cad(data / "scan2cad" / "scene0470_00").scan
    else:
        print("real data not found (set SEMLOC_DATA): simulated buildings only", file=sys.stderr)
    for b in range(buildings):
        maps[f"building {b}"] = layout(150, seed=b)
    return maps


def run(
    views: int, buildings: int, seed: int, tick: Callable[[], None]
) -> list[tuple[str, Outcome]]:
    embedder = Embedder(seed)
    found: list[tuple[str, Outcome]] = []
    for m, (name, full) in enumerate(sources(buildings).items()):
        for v, variant in enumerate(VARIANTS):
            for k in OBJECT_COUNTS:
                rng = np.random.default_rng([seed, m, v, k])
                for _ in range(views):
                    case = make_case(full, variant, k, rng)
                    for condition, (version, settings) in conditions(case, embedder).items():
                        found.append((condition, evaluate(version, name, variant, k, settings)))
                    tick()
    return found


def _cell(outcomes: list[Outcome]) -> tuple[str, str, str, str]:
    if not outcomes:
        return ("-",) * 4
    right = sum(o.right_claim for o in outcomes)
    wrong = sum(o.wrong_claim for o in outcomes)
    return (
        f"{np.mean([o.top1 for o in outcomes]):.1%}",
        f"{np.mean([o.top10 for o in outcomes]):.1%}",
        f"{right} / {wrong}",
        f"{right / len(outcomes):.1%}",
    )


def table(found: list[tuple[str, Outcome]]) -> str:
    groups: dict[tuple[str, str], Callable[[Outcome], bool]] = {}
    for source in dict.fromkeys(o.layout for _, o in found):
        for variant in VARIANTS:
            groups[(source, variant)] = lambda o, s=source, v=variant: (
                o.layout == s and o.variant == v
            )
    for k in OBJECT_COUNTS:
        groups[("all", f"{k} objects")] = lambda o, k=k: o.n_objects == k
    for variant in VARIANTS:
        groups[("all", variant)] = lambda o, v=variant: o.variant == v
    groups[("all", "all")] = lambda o: True
    names = " / ".join(CONDITIONS)
    lines = [
        f"| source | cases | runs | top-1 ({names}) | top-10 | claims right / wrong | coverage |",
        "|---|---|---|---|---|---|---|",
    ]
    for (source, which), keep in groups.items():
        cells = [_cell([o for c, o in found if c == cond and keep(o)]) for cond in CONDITIONS]
        runs = sum(1 for c, o in found if c == CONDITIONS[0] and keep(o))
        columns = [" · ".join(cell[i] for cell in cells) for i in range(4)]
        lines.append(f"| {source} | {which} | {runs} | " + " | ".join(columns) + " |")
    return "\n".join(lines)


def precision(found: list[tuple[str, Outcome]]) -> str:
    parts = []
    for cond in CONDITIONS:
        right = sum(o.right_claim for c, o in found if c == cond)
        wrong = sum(o.wrong_claim for c, o in found if c == cond)
        share = right / (right + wrong) if right + wrong else float("nan")
        parts.append(f"{cond}: {share:.1%} ({right} / {wrong})")
    return "localized precision — " + "; ".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--views", type=int, default=20, help="views per source, variant, size")
    parser.add_argument("--buildings", type=int, default=2, help="simulated buildings")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--markdown", type=Path, help="also write the table to this file")
    args = parser.parse_args()
    start = time.perf_counter()
    done = [0]

    def tick() -> None:
        done[0] += 1
        if done[0] % 50 == 0:
            print(f"{done[0]} views", file=sys.stderr)

    found = run(args.views, args.buildings, args.seed, tick)
    text = table(found) + "\n\n" + precision(found)
    text += (
        f"\n\nColumns hold: {' · '.join(CONDITIONS)}. run time {time.perf_counter() - start:.0f} s"
    )
    print(text)
    if args.markdown is not None:
        from semloc.io import write_atomic

        write_atomic(args.markdown, text + "\n")


if __name__ == "__main__":
    main()

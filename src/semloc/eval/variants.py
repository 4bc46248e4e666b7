"""Real-layout variants: local views of the real samples, clean, noisy and in a changed world.

Built from the real samples (ScanNet scene0000_00, Replica office4, 3RScan scene_1), for the
status-reliability checks of `benchmarks/real_layouts.py` and `benchmarks/status_reliability.py`:

    clean     the `k` objects nearest a viewpoint near a random object (visible-side points,
              random heading: `semloc.sim.crop`), localized in the full map;
    noisy     the same view with 5 % wrong labels (each object, drawn from the map's labels)
              and one spurious detection (a map object's shape at a random place in the view);
    dynamic   the world changed since the map was built: 10 % of the map's objects are
              deleted from the map, and 30 % of the objects were moved 0.5-2 m with a new
              heading before the robot looked (the view sees them where they are now).

Outcomes count the paper's success (15 deg / 0.5 m): top-1, top-10, the status claim and
whether it is right, and same-place duplicates in the top-10.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from semloc.decision import duplicates, local_anchor
from semloc.eval.success import is_success
from semloc.io.geometry import up_basis
from semloc.io.importers.replica import load_replica
from semloc.io.importers.rscan import load_rscan
from semloc.io.importers.scannet import load_scannet
from semloc.localizer import LocalizerConfig, localize
from semloc.maps import ObjectMap
from semloc.sim.crop import crop_with_truth, visible_points

VARIANTS = ("clean", "noisy", "dynamic")
OBJECT_COUNTS = (3, 5, 8)
WRONG_LABELS = 0.05
DELETED, MOVED, MOVE_RANGE = 0.10, 0.30, (0.5, 2.0)


def variant_maps(data: Path) -> dict[str, ObjectMap]:
    """The full maps of the three samples under the real-data folder `data`."""
    return {
        "ScanNet": load_scannet(data / "scannet" / "scene0000_00"),
        "Replica": load_replica(data / "replica" / "office4"),
        "3RScan": load_rscan(data / "3rscan_subscans" / "scene_1"),
    }


@dataclass
class Case:
    """One localization problem: the prior map, the robot's local view and the truth."""

    prior: ObjectMap
    local: ObjectMap
    truth: np.ndarray  # T_global_local
    world: ObjectMap | None = None  # the world the view was taken in (objects moved)
    pairs: list[tuple[str, str]] = field(default_factory=list)  # (world id, local id)


def make_case(full: ObjectMap, variant: str, k: int, rng: np.random.Generator) -> Case:
    """A view of `k` objects of `full` in `variant` (see the module docstring)."""
    prior, world = full, full
    if variant == "dynamic":
        prior, world = changed_world(full, rng)
    up = np.array([0.0, 0.0, 1.0]) if full.up is None else full.up
    height = float(np.median(world.positions @ up))
    anchor = world.positions[rng.integers(len(world))]
    center = anchor + up_basis(up)[:, :2] @ rng.uniform(-1, 1, 2)
    center = center + up * (height - up @ center)
    distances = np.sort(np.linalg.norm(world.positions - center, axis=1))
    radius = float(distances[min(k, len(distances)) - 1]) + 1e-6
    local, truth = crop_with_truth(world, center, radius, "random", int(rng.integers(2**31)))
    if variant == "noisy":
        local = noisy_view(local, full, center, radius, truth.T_global_local, rng)
    return Case(prior, local, truth.T_global_local, world, list(truth.pairs))


def changed_world(full: ObjectMap, rng: np.random.Generator) -> tuple[ObjectMap, ObjectMap]:
    """(prior map without 10 % of the objects, world with 30 % of them moved and turned)."""
    n = len(full)
    order = rng.permutation(n)
    deleted = set(order[: round(DELETED * n)].tolist())
    moved = set(order[n - round(MOVED * n) :].tolist())
    basis = up_basis(full.up)
    world = []
    for i, obj in enumerate(full):
        if i in moved:
            step = basis[:, :2] @ _direction(rng) * rng.uniform(*MOVE_RANGE)
            obj = obj.transformed(
                _turn_about(obj.position, basis, rng.uniform(-np.pi, np.pi), step)
            )
        world.append(obj)
    prior = full.with_objects(o for i, o in enumerate(full) if i not in deleted)
    return prior, full.with_objects(world)


def noisy_view(
    local: ObjectMap,
    full: ObjectMap,
    center: np.ndarray,
    radius: float,
    T_global_local: np.ndarray,
    rng: np.random.Generator,
) -> ObjectMap:
    """`local` with 5 % of its labels replaced and one spurious detection added."""
    labels = sorted(set(full.labels.tolist()))
    objects = []
    for obj in local:
        if rng.random() < WRONG_LABELS and len(labels) > 1:
            obj = obj.replace(label=str(rng.choice([x for x in labels if x != obj.label])))
        objects.append(obj)
    basis = up_basis(full.up)
    shape = full[int(rng.integers(len(full)))]
    place = center + basis[:, :2] @ _direction(rng) * rng.uniform(0.3, max(radius, 0.5))
    place = place + basis[:, 2] * (basis[:, 2] @ (shape.position - place))
    spurious = shape.transformed(
        _turn_about(shape.position, basis, rng.uniform(-np.pi, np.pi), place - shape.position)
    )
    spurious = spurious.replace(
        id="spurious", seen=len(objects), descriptor=None,
        points=visible_points(spurious, center),
    )  # fmt: skip
    objects.append(spurious.transformed(np.linalg.inv(T_global_local)))
    return local.with_objects(objects)


def _direction(rng: np.random.Generator) -> np.ndarray:
    angle = rng.uniform(-np.pi, np.pi)
    return np.array([np.cos(angle), np.sin(angle)])


def _turn_about(pivot: np.ndarray, basis: np.ndarray, angle: float, step: np.ndarray):
    """The 4x4 transform turning by `angle` about the up axis through `pivot`, then `step`."""
    c, s = np.cos(angle), np.sin(angle)
    R = basis @ np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]]) @ basis.T
    T = np.eye(4)
    T[:3, :3], T[:3, 3] = R, pivot - R @ pivot + step
    return T


@dataclass
class Outcome:
    """How one localization went."""

    layout: str
    variant: str
    n_objects: int
    status: str
    top1: bool
    top10: bool
    duplicates: int  # hypotheses in the top-10 at the place of a better-ranked one
    confidence: float | None
    ms: float

    @property
    def right_claim(self) -> bool:
        return self.status == "localized" and self.top1

    @property
    def wrong_claim(self) -> bool:
        return self.status == "localized" and not self.top1


def evaluate(case: Case, layout: str, variant: str, k: int, settings: dict[str, Any]) -> Outcome:
    """Localize `case` with the Localizer (config fields `settings`) and score the answer."""
    config = LocalizerConfig(**settings)
    start = time.perf_counter()
    result = localize(case.prior, case.local, config)
    ms = (time.perf_counter() - start) * 1e3
    right = [is_success(h.pose, case.truth) for h in result.hypotheses[:10]]
    best = result.best
    return Outcome(
        layout, variant, k, result.status, bool(right and right[0]), any(right),
        duplicates(result.hypotheses[:10], config.decision, local_anchor(case.local.positions)),
        None if best is None else best.confidence, ms,
    )  # fmt: skip


def run_variants(
    data: Path, crops: int, seed: int = 0, settings: dict[str, Any] | None = None, progress=None
) -> list[Outcome]:
    """`crops` cases per sample, variant and object count (seeded), localized and scored."""
    outcomes = []
    for m, (layout, full) in enumerate(variant_maps(data).items()):
        for v, variant in enumerate(VARIANTS):
            for k in OBJECT_COUNTS:
                rng = np.random.default_rng([seed, m, v, k])
                for _ in range(crops):
                    case = make_case(full, variant, k, rng)
                    outcomes.append(evaluate(case, layout, variant, k, settings or {}))
                    if progress is not None:
                        progress()
    return outcomes


def _share(flags: list[bool]) -> str:
    return f"{np.mean(flags):.1%}" if flags else "-"


def variant_table(outcomes: list[Outcome]) -> str:
    """Markdown: per variant and object count (pooled over the samples), then pooled rows."""
    lines = [
        "| variant | objects | runs | top-1 | top-10 | claims right | claims wrong | precision "
        "| coverage | duplicates in top-10 | median ms |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    groups: list[tuple[str, str, list[Outcome]]] = []
    for variant in VARIANTS:
        for k in OBJECT_COUNTS:
            groups.append((variant, str(k), [o for o in outcomes if (o.variant, o.n_objects) == (variant, k)]))  # fmt: skip
    for variant in VARIANTS:
        groups.append((variant, "all", [o for o in outcomes if o.variant == variant]))
    groups.append(("all", ">= 5", [o for o in outcomes if o.n_objects >= 5]))
    groups.append(("all", "all", list(outcomes)))
    for variant, k, group in groups:
        if not group:
            continue
        right = sum(o.right_claim for o in group)
        wrong = sum(o.wrong_claim for o in group)
        precision = f"{right / (right + wrong):.1%}" if right + wrong else "-"
        lines.append(
            f"| {variant} | {k} | {len(group)} | {_share([o.top1 for o in group])} | "
            f"{_share([o.top10 for o in group])} | {right} | {wrong} | {precision} | "
            f"{_share([o.right_claim for o in group])} | {sum(o.duplicates for o in group)} | "
            f"{np.median([o.ms for o in group]):.0f} |"
        )
    return "\n".join(lines)


def per_layout_claims(outcomes: list[Outcome]) -> str:
    """Markdown: claims right / wrong per sample and variant."""
    lines = ["| sample | variant | runs | claims right | claims wrong | coverage (>= 5) |",
             "|---|---|---|---|---|---|"]  # fmt: skip
    for layout in dict.fromkeys(o.layout for o in outcomes):
        for variant in VARIANTS:
            group = [o for o in outcomes if (o.layout, o.variant) == (layout, variant)]
            if group:
                five = [o.right_claim for o in group if o.n_objects >= 5]
                lines.append(
                    f"| {layout} | {variant} | {len(group)} | {sum(o.right_claim for o in group)}"
                    f" | {sum(o.wrong_claim for o in group)} | {_share(five)} |"
                )
    return "\n".join(lines)

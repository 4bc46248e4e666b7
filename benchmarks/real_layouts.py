"""Localization on real object layouts (issue 6): four checks on the real samples.

    SEMLOC_DATA=/path/to/shared/data/real PYTHONPATH=src python benchmarks/real_layouts.py \
        [--crops 100] [--seed 0] [--markdown TABLE.md]

1. 3RScan `scene_2` (local) against `scene_1` (global); true transform: identity.
2. Scan2CAD scene0470_00: the scan-derived map (local) against the CAD map (global); identity.
3. ScanNet scene0000_00: `--crops` crops of the map (random viewpoint near an object, radius
   1 to 3 m, visible-side points, random heading) against the full map; then again with
   centres and boxes re-fitted to the visible points (`recentre`).
4. Replica office4: the same.

Success: rotation error < 15 deg and translation error < 0.5 m (of `T_global_local`; for
crops the local frame sits at the viewpoint, so this is the robot's position error).  top-1:
the best hypothesis is right; top-10: one of the first ten is; localized: the Localizer said
`localized` and its pose is right; wrongly localized: it said `localized` with a wrong pose.
Results are grouped by the number of observed objects.
The data are found by `semloc.eval.datasets.real_data_dir()`.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import Progress

from semloc.eval.datasets import real_data_dir
from semloc.eval.success import is_success
from semloc.io.importers.replica import load_replica
from semloc.io.importers.rscan import load_rscan
from semloc.io.importers.scan2cad import load_scan2cad
from semloc.io.importers.scannet import load_scannet
from semloc.localizer import localize
from semloc.maps import ObjectMap
from semloc.sim.crop import crop_with_truth
from semloc.transforms import pose_error

BINS = ((1, 2), (3, 4), (5, 6), (7, 9), (10, 10**6))
RADII = (1.0, 1.5, 2.0, 3.0)


@dataclass
class Trial:
    """One localization attempt and how it went."""

    check: str
    n_objects: int
    top1: bool
    top10: bool
    localized: bool
    wrong_localized: bool
    status: str
    rotation_deg: float
    translation_m: float
    ms: float


def run_trial(check: str, global_map: ObjectMap, local_map: ObjectMap, truth: np.ndarray) -> Trial:
    """Localize `local_map` in `global_map` and compare with `truth` (T_global_local)."""
    start = time.perf_counter()
    result = localize(global_map, local_map)
    ms = (time.perf_counter() - start) * 1e3
    right = [is_success(h.pose, truth) for h in result.hypotheses[:10]]
    errors = (np.inf, np.inf)
    if result.hypotheses and result.hypotheses[0].pose is not None:
        errors = pose_error(result.hypotheses[0].pose, truth)
    return Trial(
        check=check,
        n_objects=len(local_map),
        top1=bool(right[:1] and right[0]),
        top10=any(right),
        localized=result.status == "localized" and bool(right[:1] and right[0]),
        wrong_localized=result.status == "localized" and not (right[:1] and right[0]),
        status=result.status,
        rotation_deg=errors[0],
        translation_m=errors[1],
        ms=ms,
    )


def crop_trials(
    check: str,
    full: ObjectMap,
    count: int,
    seed: int,
    radii: Iterable[float] = RADII,
    recentre: bool = False,
) -> list[Trial]:
    """`count` crops of `full` (viewpoint within 1 m of a random object) localized in `full`;
    with `recentre`, crop objects take the centre and box of their visible points."""
    rng = np.random.default_rng(seed)
    radii = list(radii)
    up = np.array([0.0, 0.0, 1.0]) if full.up is None else full.up
    height = float(np.median(full.positions @ up))
    trials: list[Trial] = []
    progress = Progress(transient=True, console=Console(stderr=True))
    task = progress.add_task(check, total=count)
    with progress:
        while len(trials) < count:
            _one_crop(trials, check, full, rng, radii, up, height, recentre)
            progress.update(task, completed=len(trials))
    return trials


def _one_crop(trials, check, full, rng, radii, up, height, recentre) -> None:
    """Draw one crop and append its trial (nothing when the crop holds no object)."""
    anchor = full.positions[rng.integers(len(full))]
    center = anchor + np.append(rng.uniform(-1, 1, 2), 0.0)
    center = center + up * (height - up @ center)  # at the median object height
    radius = radii[len(trials) % len(radii)]
    pose_seed = int(rng.integers(2**31))
    local, truth = crop_with_truth(full, center, radius, "random", pose_seed, recentre=recentre)
    if len(local) > 0:
        trials.append(run_trial(check, full, local, truth.T_global_local))


def all_trials(data: Path, crops: int, seed: int) -> list[Trial]:
    """The four checks on the samples under `data`."""
    trials = []
    scene_1 = load_rscan(data / "3rscan_subscans" / "scene_1")
    scene_2 = load_rscan(data / "3rscan_subscans" / "scene_2")
    trials.append(run_trial("3RScan scene_2 -> scene_1", scene_1, scene_2, np.eye(4)))
    maps = load_scan2cad(data / "scan2cad" / "scene0470_00")
    trials.append(run_trial("Scan2CAD scan -> CAD (scene0470_00)", maps.cad, maps.scan, np.eye(4)))
    scannet = load_scannet(data / "scannet" / "scene0000_00")
    replica = load_replica(data / "replica" / "office4")
    for name, full, offset in (
        ("ScanNet scene0000_00", scannet, 0),
        ("Replica office4", replica, 1),
    ):
        trials += crop_trials(f"{name} crops", full, crops, seed + offset)
        trials += crop_trials(
            f"{name} crops, re-fitted centres", full, crops, seed + offset, recentre=True
        )
    return trials


def table(trials: list[Trial]) -> str:
    """Markdown table: per check and bin of observed objects, success rates and time."""
    lines = [
        "| check | observed objects | runs | top-1 | top-10 | localized | wrongly localized "
        "| median ms |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for check in dict.fromkeys(t.check for t in trials):
        mine = [t for t in trials if t.check == check]
        groups = [(str(mine[0].n_objects), mine)]
        if len(mine) > 1:
            groups = [
                (
                    f"{lo}-{hi}" if hi < 10**6 else f"{lo}+",
                    [t for t in mine if lo <= t.n_objects <= hi],
                )
                for lo, hi in BINS
            ]
            groups.append(("all", mine))
        for name, group in groups:
            if not group:
                continue
            lines.append(
                f"| {check} | {name} | {len(group)} | {_rate(group, 'top1')} | "
                f"{_rate(group, 'top10')} | {_rate(group, 'localized')} | "
                f"{_rate(group, 'wrong_localized')} | "
                f"{np.median([t.ms for t in group]):.0f} |"
            )
    return "\n".join(lines)


def _rate(group: list[Trial], key: str) -> str:
    return f"{np.mean([getattr(t, key) for t in group]):.0%}"


def single_details(trials: list[Trial]) -> str:
    """One line per single-pair check: status and pose errors of the best hypothesis."""
    out = []
    for check in dict.fromkeys(t.check for t in trials):
        mine = [t for t in trials if t.check == check]
        if len(mine) == 1:
            t = mine[0]
            out.append(
                f"- {check}: {t.n_objects} local objects, status `{t.status}`, best hypothesis "
                f"off by {t.rotation_deg:.2f} deg / {t.translation_m:.3f} m"
            )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--crops", type=int, default=100, help="crops per crop check")
    parser.add_argument("--seed", type=int, default=0, help="seed of the crops")
    parser.add_argument("--markdown", type=Path, help="also write the table to this file")
    args = parser.parse_args(argv)
    data = real_data_dir()
    if data is None:
        print("real data not found: set SEMLOC_DATA (see ../shared/data/real)", file=sys.stderr)
        return 2
    trials = all_trials(data, args.crops, args.seed)
    text = table(trials) + "\n\n" + single_details(trials) + "\n"
    print(text)
    if args.markdown is not None:
        from semloc.io import write_atomic

        write_atomic(args.markdown, text)
    return 0


if __name__ == "__main__":
    sys.exit(main())

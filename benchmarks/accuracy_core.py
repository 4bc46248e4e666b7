"""Accuracy of the Localizer on maps full of repeated objects (the core issue's target).

Synthetic buildings (classrooms with rows of identical chairs and desks, meeting rooms with
rings of chairs, offices, kitchens, living rooms) of 150 objects; observations of the nearest
N objects around a random viewpoint with 0.1-0.4 m centre bias, one spurious detection and
5 % wrong labels, replayed one object per update.  Success is the paper's 15° / 0.5 m.

Prints, per number of observed objects: top-1 and top-10 success, how often the status is
`localized`, how often a `localized` answer is right (the precision of the claims), the
claims right / wrong, and the coverage (the share of attempts `localized` and right).

    python benchmarks/accuracy_core.py [--trials 50] [--buildings 3] [--gamma 0.8] [--tolerance 0.4]
        [--markdown TABLE.md]
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import track
from rich.table import Table

import semloc
from semloc.eval.success import first_correct_rank
from semloc.io import write_atomic
from semloc.sim.layouts import layout, observe


def run(trials: int, buildings: int, sizes: list[int], **config) -> dict[int, list]:
    rows: dict[int, list] = {n: [] for n in sizes}
    jobs = [(b, n, t) for b in range(buildings) for n in sizes for t in range(trials)]
    maps = {b: layout(150, seed=b) for b in range(buildings)}
    for b, n, t in track(jobs, description="localizing"):
        obs = observe(maps[b], n, seed=10_000 * b + 100 * n + t)
        result = semloc.localize(maps[b], obs.local_map, **config)
        rows[n].append((first_correct_rank(result.hypotheses, obs.T_global_local), result.status))
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=50)
    parser.add_argument("--buildings", type=int, default=3)
    parser.add_argument("--sizes", type=int, nargs="+", default=[3, 4, 5, 6, 8, 10])
    parser.add_argument("--gamma", type=float, default=0.8)
    parser.add_argument("--tolerance", type=float, default=0.4)
    parser.add_argument("--markdown", type=Path, help="also write the table to this file")
    parser.add_argument(
        "--rank-by", default="evidence", choices=["evidence", "residual", "score", "fitness"]
    )
    args = parser.parse_args()
    rows = run(
        args.trials,
        args.buildings,
        args.sizes,
        gamma=args.gamma,
        distance_tolerance=args.tolerance,
        rank_by=args.rank_by,
    )
    cells = table_rows(rows)
    table = Table(title=f"success at 15° / 0.5 m (γ={args.gamma}, ε={args.tolerance} m)")
    for column in COLUMNS:
        table.add_column(column, justify="right")
    for row in cells:
        table.add_row(*row)
    Console(width=120).print(table)
    if args.markdown is not None:
        lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---:|" * len(COLUMNS)]
        write_atomic(
            args.markdown, "\n".join(lines + ["| " + " | ".join(r) + " |" for r in cells]) + "\n"
        )


COLUMNS = ("observed objects", "attempts", "top-1", "top-10", "localized", "claims right / wrong",
           "precision", "coverage")  # fmt: skip


def table_rows(rows: dict[int, list]) -> list[list[str]]:
    """Per number of observed objects, then pooled over >= 5: the cells of `COLUMNS`."""
    groups = [(str(n), results) for n, results in rows.items()]
    pooled = [r for n, results in rows.items() if n >= 5 for r in results]
    if pooled and len(groups) > 1:
        groups.append(("≥ 5 (pooled)", pooled))
    out = []
    for name, results in groups:
        ranks = [r for r, _ in results]
        claims = [r == 1 for r, s in results if s == "localized"]
        out.append([
            name,
            str(len(results)),
            f"{np.mean([r == 1 for r in ranks]):.0%}",
            f"{np.mean([r is not None for r in ranks]):.0%}",
            f"{len(claims) / len(results):.0%}",
            f"{sum(claims)} / {len(claims) - sum(claims)}",
            f"{np.mean(claims):.1%}" if claims else "-",
            f"{sum(claims) / len(results):.0%}",
        ])  # fmt: skip
    return out


if __name__ == "__main__":
    main()

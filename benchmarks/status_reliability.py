"""Can a user trust `localized`?  How often each method's status claim is right, per map kind.

    python benchmarks/status_reliability.py [--methods semloc,clipper] [--sequences 6]
        [--starts 8] [--workers 2] [--min-fitness 0.3]

The attempts of `semloc bench` (same sequences, starts, offsets and seed), counted by the
method's status: `localized` and right (the best pose within 15 deg / 0.5 m), `localized` but
wrong (a false claim: the costly case for a robot), `ambiguous` (the user gets ranked
hypotheses and should wait for more objects) and `failed`.  `--min-fitness` sets semloc's
floor on the best pose's point fitness for `localized` (default: the library's, 0.3; 0 shows
how many false claims the floor removes).
"""

from __future__ import annotations

import argparse
from collections import Counter
from concurrent.futures import ProcessPoolExecutor
from functools import partial

from rich.console import Console
from rich.table import Table

from semloc.eval.protocol import Attempt, BenchConfig, run_attempts, simulate, start_keyframes


def sequence_rows(index: int, config: BenchConfig, settings: dict) -> list[dict]:
    """Every attempt of one simulated sequence, for every method and map kind."""
    seq = simulate(config, index)
    n_keyframes = len(seq.recording.detections)
    rows = []
    for start in start_keyframes(config, index, n_keyframes, config.starts):
        for kind in config.map_kinds:
            for method in config.methods:
                own = settings if method.startswith("semloc") else {}
                rows += run_attempts(seq, Attempt(index, start, kind, method, settings=own))[0]
    return rows


def outcome(row: dict) -> str:
    if row["status"] == "localized":
        return "right" if row["rank_of_first_correct"] == 1 else "wrong"
    return row["status"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--methods", default="semloc,clipper")
    parser.add_argument("--sequences", type=int, default=6)
    parser.add_argument("--starts", type=int, default=8)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--min-fitness", type=float, default=None)
    args = parser.parse_args()
    config = BenchConfig(
        sequences=args.sequences, starts=args.starts, methods=args.methods.split(",")
    )
    with ProcessPoolExecutor(args.workers) as pool:
        settings = {} if args.min_fitness is None else {"min_fitness": args.min_fitness}
        work = partial(sequence_rows, config=config, settings=settings)
        rows = [r for part in pool.map(work, range(config.sequences)) for r in part]
    counts = Counter((r["method"], r["map_kind"], outcome(r)) for r in rows)
    table = Table(title="status of each attempt (15 deg / 0.5 m)")
    for column in ("method", "map", "attempts", "localized, right", "localized, wrong",
                   "ambiguous", "failed", "claims right"):  # fmt: skip
        table.add_column(column, justify="right")
    for method in config.methods:
        for kind in config.map_kinds:
            n = {o: counts[(method, kind, o)] for o in ("right", "wrong", "ambiguous", "failed")}
            total, claims = sum(n.values()), n["right"] + n["wrong"]
            share = f"{n['right'] / claims:.0%}" if claims else "-"
            table.add_row(method, kind, str(total), str(n["right"]), str(n["wrong"]),
                          str(n["ambiguous"]), str(n["failed"]), share)  # fmt: skip
    Console(width=120).print(table)


if __name__ == "__main__":
    main()

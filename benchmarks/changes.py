"""How well `Result.changes` says what changed: moved and new objects on the real-layout variants.

The views of `benchmarks/real_layouts.py`'s variants (ScanNet scene0000_00, Replica office4,
3RScan scene_1; clean / noisy / dynamic; 3 / 5 / 8 objects; `semloc.eval.variants`): in the
dynamic variant 10 % of the map's objects are deleted from the prior map (a view of one is a
`new` object) and 30 % moved 0.5-2 m with a new heading (a view of one is `moved`); the noisy
variant's spurious detection is `new` too.  Where the
best pose is right (15° / 0.5 m), the report's `moved` pairs and `new` ids are compared with
the truth: precision and recall.  On the clean and noisy variants nothing moved: the share of
right answers without any `moved` report.  Also top-1 and the `localized` claims, per variant,
and top-1 / top-10 of the dynamic views by how many of their objects are unchanged.

    SEMLOC_DATA=/path/to/shared/data/real PYTHONPATH=src python benchmarks/changes.py \\
        [--views 20] [--seed 0] [--markdown TABLE.md]
"""

from __future__ import annotations

import argparse
import sys
import time

import numpy as np

from semloc.eval.datasets import real_data_dir
from semloc.eval.success import is_success
from semloc.eval.variants import OBJECT_COUNTS, VARIANTS, make_case, variant_maps
from semloc.localizer import localize
from semloc.maps import ObjectMap

MOVED_M = 0.05  # a world object this far from its prior place moved


def case(full: ObjectMap, variant: str, k: int, rng: np.random.Generator):
    """(prior, local view, T_global_local, true moved pairs, true new local ids)."""
    made = make_case(full, variant, k, rng)
    moved, new = set(), set(made.local.ids.tolist()) - {local for _, local in made.pairs}
    for global_id, local_id in made.pairs:
        if global_id not in made.prior:
            new.add(local_id)
        elif (
            np.linalg.norm(made.world.get(global_id).position - made.prior.get(global_id).position)
            > MOVED_M
        ):
            moved.add((global_id, local_id))
    return made.prior, made.local, made.truth, moved, new


def run(data, views: int, seed: int) -> list[dict]:
    rng = np.random.default_rng(seed)
    rows = []
    for name, full in variant_maps(data).items():
        for variant in VARIANTS:
            for k in OBJECT_COUNTS:
                for _ in range(views):
                    prior, local, truth, moved, new = case(full, variant, k, rng)
                    result = localize(prior, local)
                    right = result.pose is not None and is_success(result.pose, truth)
                    top10 = any(is_success(h.pose, truth) for h in result.hypotheses[:10])
                    found_moved = {(m.global_id, m.local_id) for m in result.changes.moved}
                    rows.append(dict(
                        layout=name, variant=variant, k=k, right=right, top10=top10,
                        unchanged=len(local) - len(moved) - len(new),
                        claimed=result.status == "localized", moved=moved, new=new,
                        found_moved=found_moved, found_new=set(result.changes.new),
                    ))  # fmt: skip
    return rows


def _ratio(hits: int, total: int) -> str:
    return f"{hits / total:.0%} ({hits}/{total})" if total else "-"


def table(rows: list[dict]) -> str:
    lines = [
        "| variant | objects | views | top-1 | claims right / wrong | moved precision | "
        "moved recall | new precision | new recall | right answers without a false `moved` |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for variant in VARIANTS:
        for k in (*OBJECT_COUNTS, "all"):
            group = [r for r in rows if r["variant"] == variant and k in (r["k"], "all")]
            right = [r for r in group if r["right"]]
            m_hit = sum(len(r["found_moved"] & r["moved"]) for r in right)
            n_hit = sum(len(r["found_new"] & r["new"]) for r in right)
            clean = sum(not (r["found_moved"] - r["moved"]) for r in right)
            claims = [r for r in group if r["claimed"]]
            lines.append(
                f"| {variant} | {k} | {len(group)} | {len(right) / len(group):.0%} | "
                f"{sum(r['right'] for r in claims)} / {sum(not r['right'] for r in claims)} | "
                f"{_ratio(m_hit, sum(len(r['found_moved']) for r in right))} | "
                f"{_ratio(m_hit, sum(len(r['moved']) for r in right))} | "
                f"{_ratio(n_hit, sum(len(r['found_new']) for r in right))} | "
                f"{_ratio(n_hit, sum(len(r['new']) for r in right))} | "
                f"{_ratio(clean, len(right))} |"
            )
    return "\n".join(lines)


def unchanged_table(rows: list[dict]) -> str:
    """Dynamic views by how many of their objects are unchanged (neither moved nor new): what
    a place is found from."""
    lines = ["| objects | unchanged objects in view | views | top-1 | top-10 |",
             "|---:|---:|---:|---:|---:|"]  # fmt: skip
    dynamic = [r for r in rows if r["variant"] == "dynamic"]
    for k in OBJECT_COUNTS:
        for u in sorted({r["unchanged"] for r in dynamic if r["k"] == k}):
            group = [r for r in dynamic if r["k"] == k and r["unchanged"] == u]
            lines.append(
                f"| {k} | {u} | {len(group)} | {np.mean([r['right'] for r in group]):.0%} | "
                f"{np.mean([r['top10'] for r in group]):.0%} |"
            )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--views", type=int, default=20, help="views per sample, variant, size")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--markdown", help="also write the table to this file")
    args = parser.parse_args(argv)
    data = real_data_dir()
    if data is None:
        print("real data not found: set SEMLOC_DATA (see ../shared/data/real)", file=sys.stderr)
        return 2
    start = time.perf_counter()
    rows = run(data, args.views, args.seed)
    text = table(rows) + "\n\nDynamic views by unchanged objects:\n\n" + unchanged_table(rows)
    text += f"\n\nrun time {time.perf_counter() - start:.0f} s"
    print(text)
    if args.markdown:
        from semloc.io import write_atomic

        write_atomic(args.markdown, text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())

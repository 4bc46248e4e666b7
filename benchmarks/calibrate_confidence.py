"""Fit the shipped confidence model on simulated benchmark attempts and show its reliability.

    PYTHONPATH=src python benchmarks/calibrate_confidence.py [--sequences 4] [--starts 6]
        [--seed 1] [--precision 0.995] [--write] [--figure docs/img/reliability.png]

Collects every hypothesis of the protocol's semloc attempts (`semloc.eval.calibration`) on
simulated sequences of `--seed` (not the benchmark's seed 0, and never the real layouts, which
stay held out), fits the evidence and confidence logistic models and the operating point for
`--precision` of the claims, prints the model and a reliability table (predicted confidence vs
observed share right) on the fitting attempts and on held-out simulated attempts (seed 0), and
with `--write` replaces `src/semloc/confidence_model.py`.
"""

from __future__ import annotations

import argparse
import json
import pprint
import sys
from pathlib import Path

import numpy as np

from semloc.decision import MODEL_MODULE
from semloc.eval.calibration import best_of_answers, collect, confidences, fit, reliability
from semloc.eval.protocol import BenchConfig
from semloc.io import write_atomic


def reliability_table(name: str, samples, model) -> str:
    predicted = confidences(samples, model)
    right = np.array([s.right for s in samples], dtype=float)
    lines = [f"{name}: {len(samples)} hypotheses", "| confidence | hypotheses | mean predicted "
             "| observed right |", "|---|---|---|---|"]  # fmt: skip
    for lo, hi, n, p, o in reliability(predicted, right):
        lines.append(f"| {lo:.1f}-{hi:.1f} | {n} | {p:.3f} | {o:.3f} |")
    claims = [(s, c) for s, c in best_of_answers(samples, model)
              if c >= model.min_confidence and s.pairs >= 3 and s.fitness >= 0.3]  # fmt: skip
    answers = len({s.answer for s in samples})
    right_claims = sum(s.right for s, _ in claims)
    lines.append(
        f"\nclaims at min_confidence {model.min_confidence:.3f}: {right_claims} right, "
        f"{len(claims) - right_claims} wrong, of {answers} answers"
    )
    return "\n".join(lines)


def figure(path: Path, sets) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(4.5, 4.5))
    ax.plot([0, 1], [0, 1], color="grey", lw=1, ls="--", label="perfect")
    for name, samples, model in sets:
        predicted = confidences(samples, model)
        right = np.array([s.right for s in samples], dtype=float)
        rows = reliability(predicted, right)
        ax.plot([r[3] for r in rows], [r[4] for r in rows], marker="o", label=name)
    ax.set_xlabel("predicted confidence")
    ax.set_ylabel("observed share right (15° / 0.5 m)")
    ax.set_title("reliability of semloc's confidence")
    ax.legend(loc="upper left", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--sequences", type=int, default=4)
    parser.add_argument("--starts", type=int, default=6)
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--holdout-sequences", type=int, default=2)
    parser.add_argument("--precision", type=float, default=0.995)
    parser.add_argument("--write", action="store_true", help=f"replace {MODEL_MODULE}")
    parser.add_argument("--figure", type=Path, help="also draw the reliability diagram (PNG)")
    args = parser.parse_args(argv)
    config = BenchConfig(sequences=args.sequences, starts=args.starts, seed=args.seed, real=False)
    samples = collect(config)
    data = (f"semloc attempts of the benchmark protocol: seed {args.seed}, {args.sequences} "
            f"sequences, {args.starts} starts, map kinds {', '.join(config.map_kinds)}; "
            f"{len(samples)} hypotheses")  # fmt: skip
    model = fit(samples, args.precision, data)
    model = model.model_copy(update={"fitted_by": " ".join(["benchmarks/calibrate_confidence.py",
                                                            *(argv or sys.argv[1:])])})  # fmt: skip
    print(json.dumps(model.model_dump(), indent=2))
    print(reliability_table("fitting attempts", samples, model))
    holdout = collect(BenchConfig(sequences=args.holdout_sequences, starts=args.starts, seed=0))
    print(reliability_table("held-out simulated attempts (seed 0)", holdout, model))
    if args.figure is not None:
        figure(args.figure, [(f"fitting (seed {args.seed})", samples, model),
                             ("held out (seed 0)", holdout, model)])  # fmt: skip
    if args.write:
        doc = '"""The shipped confidence model\'s coefficients (see `semloc.decision.ConfidenceModel`).\n\n'
        doc += 'Written by `benchmarks/calibrate_confidence.py --write`; data, not I/O: the core reads no files.\n"""\n\n'
        write_atomic(
            MODEL_MODULE,
            doc
            + "SHIPPED = "
            + pprint.pformat(model.model_dump(), width=96, sort_dicts=False)
            + "\n",
        )
        print(f"wrote {MODEL_MODULE}")
    return 0


if __name__ == "__main__":
    sys.exit(main())

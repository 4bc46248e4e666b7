"""Figures and report.md of a benchmark run (the paper's plots), all written atomically.

- comparison.png: per map kind (columns), recall vs translation tolerance at top-10 (row 1) and
  recall vs k at 0.5 m / 15 deg (row 2), one line per method;
- ablation_gamma.png: semloc's recall at top-1/5/10/20 and time per update vs gamma;
- ablation_objects.png: recall at top-10 and time per update vs the number of local objects,
  per method (all map kinds pooled).
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from semloc.baselines import METHODS
from semloc.eval.protocol import NIGHT, bench_kinds
from semloc.eval.recall import (
    HYPOTHESIS_COLUMNS,
    RESULT_COLUMNS,
    format_rows,
    group_by,
    recall_at_k,
    recall_vs_tolerance,
    summary,
)  # fmt: skip
from semloc.io import write_atomic
from semloc.sim.mapkinds import MAP_KINDS

TOLERANCES = np.round(np.arange(0.05, 1.501, 0.05), 3)
KS = list(range(1, 21))
_SIMULATED_ORDER = ["reconstruction", NIGHT, *list(MAP_KINDS)[1:]]
_KIND_ORDER = {kind: i for i, kind in enumerate(
    [*_SIMULATED_ORDER, *(f"real {k}" for k in _SIMULATED_ORDER)])}  # fmt: skip
"""Simulated map kinds first (the night queries beside their day half, reconstruction), then
those of the real walks (eval.realwalks) in the same order."""
OBJECT_BINS = [(3, 4), (5, 6), (7, 9), (10, 14), (15, 19), (20, 29), (30, 1000)]


def _style(method: str) -> dict:
    """semloc bold; its descriptor variants dashed, so they read as variants of it."""
    width = 2.6 if method == "semloc" else 1.5
    dashed = method.startswith("semloc+")
    color = METHODS[method].color if method in METHODS else "C6"
    return {"linewidth": width, "color": color,
            "linestyle": "--" if dashed else "-"}  # fmt: skip


def comparison_figure(rows, hyps, methods: Sequence[str], kinds: Sequence[str]):
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(kinds), figsize=(4.6 * len(kinds), 7.2), dpi=90,
                             squeeze=False)  # fmt: skip
    by_kind = group_by(rows, "map_kind")
    hyp_by = group_by(hyps, "method", "map_kind")
    for col, kind in enumerate(kinds):
        kind_rows = group_by(by_kind.get((kind,), []), "method")
        for method in methods:
            mrows = kind_rows.get((method,), [])
            if not mrows:
                continue
            curve = recall_vs_tolerance(mrows, TOLERANCES, hyp_by.get((method, kind), []), 10)
            axes[0, col].plot(TOLERANCES, curve, label=method, **_style(method))
            axes[1, col].plot(KS, [recall_at_k(mrows, k) for k in KS], label=method,
                              **_style(method))  # fmt: skip
        axes[0, col].set_title(f"{kind} map")
        axes[0, col].set_xlabel("translation tolerance (m), top-10, rotation < 15°")
        axes[1, col].set_xlabel("top-k hypotheses (0.5 m / 15°)")
        for ax in axes[:, col]:
            ax.set_ylim(0, 1.02)
            ax.grid(alpha=0.3)
    axes[0, 0].set_ylabel("recall")
    axes[1, 0].set_ylabel("recall")
    axes[0, 0].axvline(0.5, color="grey", linestyle=":", linewidth=1)
    axes[1, -1].legend(loc="lower right", fontsize=9)
    fig.tight_layout()
    return fig


def gamma_figure(ablation: Sequence[dict]):
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8), dpi=90)
    groups = group_by(ablation, "method")
    gammas = sorted(float(m[0].split("=")[1]) for m in groups)
    for k in (1, 5, 10, 20):
        left.plot(gammas, [recall_at_k(groups[(f"semloc gamma={g:g}",)], k) for g in gammas],
                  marker="o", label=f"top-{k}")  # fmt: skip
    times = [np.median([r["ms"] for r in groups[(f"semloc gamma={g:g}",)]]) for g in gammas]
    right.plot(gammas, times, marker="o", color="black")
    left.set(xlabel="γ (merge threshold)", ylabel="recall (0.5 m / 15°)", ylim=(0, 1.02))
    right.set(xlabel="γ (merge threshold)", ylabel="median time per update (ms)")
    left.legend(fontsize=9)
    for ax in (left, right):
        ax.grid(alpha=0.3)
    fig.tight_layout()
    return fig


def _bin_label(lo: int, hi: int) -> str:
    return f"{lo}+" if hi >= 1000 else f"{lo}-{hi}" if hi > lo else str(lo)


def objects_figure(rows: Sequence[dict], methods: Sequence[str]):
    import matplotlib.pyplot as plt

    fig, (left, right) = plt.subplots(1, 2, figsize=(10, 3.8), dpi=90)
    by_method = group_by(rows, "method")
    bins = [(lo, hi) for lo, hi in OBJECT_BINS if any(lo <= r["n_local"] <= hi for r in rows)]
    x = np.arange(len(bins))
    for method in methods:
        mrows = by_method.get((method,), [])
        recall, ms = [], []
        for lo, hi in bins:
            inside = [r for r in mrows if lo <= r["n_local"] <= hi]
            recall.append(recall_at_k(inside, 10) if len(inside) >= 3 else np.nan)
            ms.append(np.median([r["ms"] for r in inside]) if len(inside) >= 3 else np.nan)
        left.plot(x, recall, marker="o", label=method, **_style(method))
        right.plot(x, ms, marker="o", label=method, **_style(method))
    labels = [_bin_label(lo, hi) for lo, hi in bins]
    for ax in (left, right):
        ax.set_xticks(x, labels)
        ax.set_xlabel("local objects")
        ax.grid(alpha=0.3)
    left.set(ylabel="recall at top-10 (0.5 m / 15°)", ylim=(0, 1.02))
    right.set(ylabel="median time per update (ms)")
    if any(np.isfinite(line.get_ydata()).any() for line in right.get_lines()):
        right.set_yscale("log")
    left.legend(fontsize=8)
    fig.tight_layout()
    return fig


def _cell(value, fmt: str = "{:.2f}") -> str:
    return (
        "–"
        if value is None or (isinstance(value, float) and np.isnan(value))
        else fmt.format(value)
    )


def _table(head: Sequence[str], body: Sequence[Sequence[str]]) -> str:
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    lines += ["| " + " | ".join(cells) + " |" for cells in body]
    return "\n".join(lines) + "\n"


def _kinds(rows: Sequence[dict]) -> list[str]:
    """The map kinds present, simulated ones in their usual order, then any other ('real')."""
    return sorted({r["map_kind"] for r in rows}, key=lambda k: (_KIND_ORDER.get(k, 9), k))


def summary_table(rows: Sequence[dict], methods: Sequence[str]) -> str:
    """Markdown table: recall@1 / recall@10 per method (rows) and map kind (columns), ms."""
    stats = {(s["method"], s["map_kind"]): s for s in summary(rows)}
    by_method = group_by(rows, "method")
    kinds = _kinds(rows)
    body = []
    for method in methods:
        cells = [f"{_cell(s['recall@1'])} / {_cell(s['recall@10'])}" if s else "–"
                 for s in (stats.get((method, kind)) for kind in kinds)]  # fmt: skip
        ms = [r["ms"] for r in by_method.get((method,), [])]
        body.append([method, *cells, _cell(float(np.median(ms)) if ms else None, "{:.0f}")])
    head = ["method", *(f"{k}: top-1 / top-10" for k in kinds), "median ms / update"]
    return _table(head, body)


def claims_table(rows: Sequence[dict], methods: Sequence[str]) -> str:
    """Markdown: per method and map kind, `localized` claims right / wrong, their precision and
    the coverage (share of attempts `localized` and right: the best pose within 15° / 0.5 m)."""
    body = []
    for method in methods:
        for kind in _kinds(rows):
            group = [r for r in rows if r["method"] == method and r["map_kind"] == kind]
            if not group:
                continue
            claims = [r for r in group if r.get("status") == "localized"]
            right = sum(r["rank_of_first_correct"] == 1 for r in claims)
            precision = _cell(right / len(claims) if claims else None, "{:.1%}")
            body.append([method, kind, str(len(group)), str(right), str(len(claims) - right),
                         precision, _cell(right / len(group), "{:.1%}")])  # fmt: skip
    head = ["method", "map", "attempts", "claims right", "claims wrong", "precision", "coverage"]
    return _table(head, body)


def write_outputs(out: Path, config, rows, hyps, ablation, seconds: float) -> list[Path]:
    from semloc.pictures.viz import save_figure

    files = []
    for name, data, columns in (
        ("results.csv", rows, RESULT_COLUMNS),
        ("hypotheses.csv", hyps, HYPOTHESIS_COLUMNS),
        ("ablation.csv", ablation, RESULT_COLUMNS),
    ):
        files.append(write_atomic(out / name, format_rows(data, columns)))
    methods = [m for m in config.methods if any(r["method"] == m for r in rows)]
    kinds = [k for k in bench_kinds(config) if any(r["map_kind"] == k for r in rows)]
    figures = []
    if kinds:  # simulated rows (none with --sequences 0)
        figures.append(save_figure(comparison_figure(rows, hyps, methods, kinds),
                                   out / "comparison.png"))  # fmt: skip
        sim = [r for r in rows if r["map_kind"] != "real"]
        figures.append(save_figure(objects_figure(sim, methods), out / "ablation_objects.png"))
    if ablation:
        figures.append(save_figure(gamma_figure(ablation), out / "ablation_gamma.png"))
    files += figures
    text = report_text(config, rows, ablation, methods, seconds, [f.name for f in figures])
    write_atomic(out / "report.md", text)
    write_atomic(out / "config.json", json.dumps(config.model_dump(), indent=1) + "\n")
    return [*files, out / "report.md", out / "config.json"]


def _offset_name(offset: int) -> str:
    return "first (> 2 objects)" if offset == 0 else f"+{offset} keyframes"


def _attempt_cell(group: Sequence[dict]) -> str:
    if not group:
        return "–"
    n_local = np.median([r["n_local"] for r in group])
    ms = np.median([r["ms"] for r in group])
    return f"{_cell(recall_at_k(group, 1))} (~{n_local:.0f} objects, {ms:.0f} ms)"


def attempt_tables(rows: Sequence[dict], methods: Sequence[str]) -> str:
    """Markdown: top-1 by attempt (simulated kinds pooled, with the median number of local
    objects and time per update), then top-1 at the first attempt per simulated map kind."""
    sim = [r for r in rows if r["map_kind"] != "real"]
    if not sim:
        return ""
    offsets = sorted({r["offset"] for r in sim})
    by_offset = group_by(sim, "method", "offset")
    body = [[method, *(_attempt_cell(by_offset.get((method, offset), [])) for offset in offsets)]
            for method in methods]  # fmt: skip
    text = _table(["method", *map(_offset_name, offsets)], body)
    kinds = _kinds(sim)
    first = group_by([r for r in sim if r["offset"] == offsets[0]], "method", "map_kind")
    body = [[method, *(_cell(recall_at_k(first.get((method, k), []), 1)) for k in kinds)]
            for method in methods]  # fmt: skip
    return text + "\nFirst attempt, top-1 per map kind:\n\n" + _table(["method", *kinds], body)


def gamma_table(ablation: Sequence[dict]) -> str:
    """Markdown table of the γ ablation (rows labelled `semloc gamma=G`): recall at top-k, ms."""
    body = []
    for (method,), group in sorted(group_by(ablation, "method").items(),
                                   key=lambda item: float(item[0][0].split("=")[1])):  # fmt: skip
        recalls = [_cell(recall_at_k(group, k)) for k in (1, 5, 10, 20)]
        ms = _cell(float(np.median([r["ms"] for r in group])), "{:.0f}")
        body.append([method.split("=")[1], str(len(group)), *recalls, ms])
    return _table(["γ", "attempts", "top-1", "top-5", "top-10", "top-20", "median ms"], body)


def report_text(config, rows, ablation, methods, seconds: float, figures: list[str]) -> str:
    attempts = len(group_by(rows, "map_kind", "sequence", "start", "offset"))
    text = [
        "# semloc bench report\n\n",
        f"{config.sequences} simulated sequences ({config.size} worlds, {config.keyframes} "
        f"keyframes, seed {config.seed}), {config.starts} random starts each; at every start "
        "relocalization when more than 2 objects are seen, then +15 and +30 keyframes; global "
        f"maps: {', '.join(config.map_kinds)}. {attempts} attempts per method, "
        f"{len(rows)} rows in results.csv; run time {seconds:.0f} s.\n\n",
        "Success: the pose is within 15° and 0.5 m. top-k: one of the first k hypotheses is. "
        "All methods recover poses with the same `semloc.pose.estimate_pose`. The column "
        "'real' (when the importers' samples are present) holds one attempt per pair: 3RScan "
        "scene_2 in scene_1 and the Scan2CAD scan map of scene0470_00 in its CAD map "
        "(object maps: image methods such as SIFT have no images there, '–'). The column "
        "'night' is the day / night pair: the reconstruction map, made by day, with the "
        "query images relit at night; object methods see the same objects at night, so "
        "their night rows repeat their reconstruction rows.\n\n",
        "## Recall (top-1 / top-10) and time per update\n\n",
        summary_table(rows, methods),
        "\n## Can `localized` be trusted? Claims and coverage per map kind\n\n",
        claims_table(rows, methods),
        "\n## Top-1 by attempt (simulated maps)\n\n",
        attempt_tables(rows, methods),
    ]
    if ablation:
        text.append("\n## Ablation over γ (semloc, reconstruction map)\n\n")
        text.append(gamma_table(ablation))
    text.append("\n## Figures\n")
    captions = {
        "comparison.png": "Recall vs translation tolerance (top-10) and recall vs k "
        "(0.5 m / 15°), per global map kind.",
        "ablation_objects.png": "Recall at top-10 and time per update vs local objects.",
        "ablation_gamma.png": "semloc: recall at top-k and time per update vs γ.",
    }
    for name in figures:
        text.append(f"\n![{name}]({name})\n\n{captions.get(name, '')}\n")
    text.append("\nFiles: results.csv (one row per attempt and method), hypotheses.csv (every "
                "hypothesis' errors), ablation.csv, config.json.\n")  # fmt: skip
    return "".join(text)

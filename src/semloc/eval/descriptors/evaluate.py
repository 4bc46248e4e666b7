"""Evaluation of the descriptors (`semloc descriptors-eval`): retrieval, real check, δ, gate.

1. Simulated retrieval: the gallery holds one whole-surface (CAD-style) view of every instance
   (class, style); queries are noisy partial views of the held-out instances (never trained
   on) and, for reference, of the training instances.  Reported: top-1 / top-5 of the right
   instance among all gallery objects and among those of the query's class.
2. Real check: Scan2CAD scene0470_00, the scan segments (cut out of the ScanNet mesh by the
   annotated boxes) against the real ShapeNet CAD models; skipped without the data.  Two
   chairs share one ShapeNet model: retrieving the twin counts as right (same shape).
3. Calibration: true (global, local) pairs of simulated sequences (local objects fused from
   noisy detections vs the reconstruction and the CAD map); δ is the 98 % quantile of their
   descriptor distances; reported: share of true pairs that pass and share of the wrong
   same-label candidates removed, per map kind.
4. Gate effect: relocalization attempts on the same sequences with and without descriptors:
   local maps fused over `window` keyframes from random starts, localized against the
   reconstruction and the CAD map (closed-form poses, no ICP: the gate changes associations,
   not the refinement); success = top-1 pose within 15° and 0.5 m.
"""

from __future__ import annotations

import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.table import Table

from semloc.association import CandidateIndex, canonical_label
from semloc.descriptors import MIN_POINTS, compute_batch, with_descriptors
from semloc.eval.datasets import real_sample
from semloc.eval.descriptors.data import full_view, instances, partial_view
from semloc.io import write_atomic
from semloc.io.importers.scan2cad import load_scan2cad
from semloc.localizer import LocalizerConfig, localize
from semloc.sim.scenario import simulate_sequence
from semloc.transforms import pose_error


@dataclass
class EvalConfig:
    kinds: list[str] = field(default_factory=lambda: ["geometric", "voxnet"])
    seed: int = 1
    views: int = 20
    sequences: int = 3
    keyframes: int = 40
    attempts: int = 8
    window: int = 6
    quantile: float = 0.98


def _topk(distances: np.ndarray, true_index: int, candidates: np.ndarray) -> int:
    """Rank (0 = best) of the true gallery entry among `candidates` by distance."""
    d = distances[candidates]
    return int(np.sum(d < distances[true_index]))


def retrieval(kind: str, seed: int, views: int) -> dict:
    """Top-1 / top-5 retrieval of the right instance from partial views (see module doc)."""
    every = instances("all")
    rng = np.random.default_rng([seed, 401])
    gallery = compute_batch([full_view(label, style, rng) for label, style in every], kind)
    labels = np.array([label for label, _ in every])
    out = {}
    for split in ("held_out", "train"):
        ranks_all, ranks_class = [], []
        true_d, wrong_class_d = [], []
        for label, style in instances(split):
            queries = [partial_view(label, style, rng) for _ in range(views)]
            q = compute_batch(queries, kind)
            t = every.index((label, style))
            same = np.flatnonzero(labels == label)
            for row in q:
                d = np.linalg.norm(gallery - row, axis=1)
                ranks_all.append(_topk(d, t, np.arange(len(every))))
                ranks_class.append(_topk(d, t, same))
                true_d.append(d[t])
                wrong_class_d.extend(d[same[same != t]].tolist())
        ra, rc = np.array(ranks_all), np.array(ranks_class)
        out[split] = {
            "queries": len(ra),
            "all": {"top1": float(np.mean(ra < 1)), "top5": float(np.mean(ra < 5))},
            "same_class": {"top1": float(np.mean(rc < 1)), "top5": float(np.mean(rc < 5))},
            "candidates_all": len(every),
            "true_distance_median": float(np.median(true_d)),
            "same_class_wrong_distance_median": float(np.median(wrong_class_d)),
        }
    return out


def scan2cad_check(kind: str) -> dict | None:
    """Scan segments vs CAD models of Scan2CAD scene0470_00; None when the data is absent."""

    folder = real_sample("scan2cad", "scene0470_00")
    if folder is None:
        return None
    maps = load_scan2cad(folder)
    if maps.scan is None:
        return None
    cad = [o for o in maps.cad if o.points is not None and len(o.points) >= MIN_POINTS]
    scan = [o for o in maps.scan if o.id in {c.id for c in cad} and len(o.points) >= MIN_POINTS]
    g = compute_batch([o.points for o in cad], kind)
    q = compute_batch([o.points for o in scan], kind)
    ids = [o.id for o in cad]
    labels = np.array([o.label for o in cad])
    shape = _cad_models(folder)
    rows = []
    for obj, row in zip(scan, q):
        d = np.linalg.norm(g - row, axis=1)
        t = ids.index(obj.id)
        # a CAD object of the very same ShapeNet model is as right as the annotated one
        other = np.array([shape.get(i) != shape.get(obj.id) for i in ids])
        same = np.flatnonzero(labels == obj.label)
        rows.append(
            {
                "id": obj.id,
                "label": obj.label,
                "rank_all": _topk(d, t, np.flatnonzero(other)),
                "rank_same_class": _topk(d, t, same[other[same]]),
                "same_class_candidates": len(same),
                "true_distance": float(d[t]),
                "nearest_wrong_same_class": float(np.min(d[same[other[same]]]))
                if np.any(other[same])
                else None,
            }
        )
    ra = np.array([r["rank_all"] for r in rows])
    rc = np.array([r["rank_same_class"] for r in rows])
    return {
        "scene": maps.cad.name,
        "cad_models": len(cad),
        "scan_segments": len(scan),
        "all": {"top1": float(np.mean(ra < 1)), "top5": float(np.mean(ra < 5))},
        "same_class": {"top1": float(np.mean(rc < 1)), "top5": float(np.mean(rc < 5))},
        "objects": rows,
    }


def _cad_models(folder: Path) -> dict[str, str]:
    """Object id -> ShapeNet model id of a Scan2CAD annotation (same model = same shape)."""
    try:
        document = json.loads((folder / "scan2cad_annotation.json").read_text(encoding="utf-8"))
        entry = document[0] if isinstance(document, list) else document
        return {
            str(i): f"{m['catid_cad']}/{m['id_cad']}" for i, m in enumerate(entry["aligned_models"])
        }
    except (OSError, ValueError, KeyError, IndexError, TypeError):
        return {}


def _sequences(n: int, keyframes: int):

    return [
        simulate_sequence(500 + i, "small", ["reconstruction", "cad"], n_keyframes=keyframes)
        for i in range(n)
    ]


def pair_distances(kind: str, sequences) -> dict[str, dict[str, list[float]]]:
    """Descriptor distances of true pairs and of wrong same-label candidates, per map kind."""

    out: dict[str, dict[str, list[float]]] = {}
    for seq in sequences:
        local = [o for o in seq.local_map if o.points is not None and len(o.points) >= MIN_POINTS]
        fl = compute_batch([o.points for o in local], kind)
        for map_kind, gmap in seq.global_maps.items():
            entry = out.setdefault(map_kind, {"true": [], "wrong": []})
            fg = compute_batch([o.points for o in gmap], kind)
            labels = [canonical_label(x, {}) for x in gmap.labels]
            for obj, f in zip(local, fl):
                truth = seq.local_truth.get(obj.id)
                label = canonical_label(obj.label, {})
                for gi, g in enumerate(gmap):
                    if labels[gi] != label:
                        continue
                    d = float(np.linalg.norm(fg[gi] - f))
                    entry["true" if g.id == truth else "wrong"].append(d)
    return out


def calibrate(distances: dict[str, dict[str, list[float]]], quantile: float) -> dict:
    """δ = the `quantile` of all true-pair distances, rounded up to the next 0.01 (so at least
    that share passes `d < δ`); the share of true pairs passing and of wrong candidates
    removed per map kind, and the trade-off at other quantiles."""
    pooled = np.concatenate([np.asarray(v["true"]) for v in distances.values()])
    # the smallest multiple of 0.01 above the quantile (pairs pass when distance < δ)
    delta = (math.floor(float(np.quantile(pooled, quantile)) * 100) + 1) / 100
    per_kind = {}
    for map_kind, v in distances.items():
        t, w = np.asarray(v["true"]), np.asarray(v["wrong"])
        per_kind[map_kind] = {
            "true_pairs": len(t),
            "true_pass": float(np.mean(t < delta)) if len(t) else None,
            "wrong_candidates": len(w),
            "wrong_removed": float(np.mean(w >= delta)) if len(w) else None,
            "true_distance_quantiles": {
                str(q): float(np.quantile(t, q)) for q in (0.5, 0.9, quantile)
            }
            if len(t)
            else None,
            "wrong_distance_median": float(np.median(w)) if len(w) else None,
        }
    wrong = np.concatenate([np.asarray(v["wrong"]) for v in distances.values()])
    tradeoff = []
    for q in (0.5, 0.8, 0.9, 0.95, quantile):
        bound = float(np.quantile(pooled, q))
        tradeoff.append(
            {"true_pass": q, "delta": bound, "wrong_removed": float(np.mean(wrong >= bound))}
        )
    return {
        "delta": delta,
        "quantile": quantile,
        "true_pairs": len(pooled),
        "maps": per_kind,
        "tradeoff": tradeoff,
        "paper_delta_0.5": {
            "true_pass": float(np.mean(pooled < 0.5)),
            "wrong_removed": float(np.mean(wrong >= 0.5)),
        },
    }


def gate_effect(
    kind: str,
    delta: float,
    sequences,
    attempts: int,
    seed: int,
    window: int = 6,
    refine: bool = False,
) -> dict:
    """Relocalization success (top-1 pose within 15° / 0.5 m) with and without descriptors."""

    rng = np.random.default_rng([seed, 409])
    base = {"refine": refine}  # ICP does not change which associations exist
    settings = {
        "without": LocalizerConfig(**base),
        "with": LocalizerConfig(descriptor=kind, descriptor_delta=delta, **base),
    }
    out: dict = {}
    for seq in sequences:
        n = len(seq.recording.detections)
        for start in rng.integers(0, max(1, n - window), size=attempts).tolist():
            replay = seq.replay(int(start), min(n, int(start) + window))
            for map_kind, gmap in seq.global_maps.items():
                for name, cfg in settings.items():
                    tick = time.perf_counter()
                    result = localize(gmap, replay.local_map, cfg)
                    ms = (time.perf_counter() - tick) * 1e3
                    ok = False
                    if result.pose is not None:
                        rot, trans = pose_error(result.pose, replay.T_global_local)
                        ok = rot < 15 and trans < 0.5
                    entry = out.setdefault(map_kind, {}).setdefault(
                        name,
                        {"attempts": 0, "success": 0, "localized": 0, "ms": 0.0, "candidates": 0},
                    )
                    entry["candidates"] += _candidates(gmap, replay.local_map, cfg)
                    entry["attempts"] += 1
                    entry["success"] += int(ok)
                    entry["localized"] += int(result.status == "localized" and ok)
                    entry["ms"] += ms
    for by_name in out.values():
        for entry in by_name.values():
            entry["recall"] = entry["success"] / max(entry["attempts"], 1)
            entry["ms"] = entry["ms"] / max(entry["attempts"], 1)
            entry["candidates"] = entry["candidates"] / max(entry["attempts"], 1)
    return out


def _candidates(gmap, local_map, cfg) -> int:
    """Singleton candidates (initial association sets) of a local map under a config."""

    a = cfg.association
    if a.descriptor is not None:
        gmap, local_map = (
            with_descriptors(gmap, a.descriptor),
            with_descriptors(local_map, a.descriptor),
        )
    index = CandidateIndex(gmap, a)
    return sum(len(index.candidates(o)) for o in local_map)


def run_evaluation(config: EvalConfig, log: Callable[[str], None] = print) -> dict:
    """All four parts for every kind in `config.kinds`."""
    report: dict = {"config": config.__dict__, "kinds": {}}
    sequences = None
    if config.sequences:
        log(f"simulating {config.sequences} sequences ...")
        sequences = _sequences(config.sequences, config.keyframes)
    for kind in config.kinds:
        log(f"{kind}: retrieval on simulated views ...")
        entry: dict = {"retrieval": retrieval(kind, config.seed, config.views)}
        real = scan2cad_check(kind)
        entry["scan2cad"] = real
        if real is None:
            log(f"{kind}: Scan2CAD sample not found (set SEMLOC_DATA): real check skipped")
        if sequences:
            log(f"{kind}: calibration and gate effect ...")
            calibration = calibrate(pair_distances(kind, sequences), config.quantile)
            entry["calibration"] = calibration
            entry["gate"] = gate_effect(
                kind, calibration["delta"], sequences, config.attempts, config.seed, config.window
            )
        report["kinds"][kind] = entry
    return report


def print_report(report: dict, console) -> None:
    """Rich tables of a report."""

    for kind, entry in report["kinds"].items():
        table = Table(title=f"{kind}: retrieval (top-1 / top-5)", title_justify="left")
        for column in ("queries", "n", "all", "same class"):
            table.add_column(column, justify="right")
        for split, r in entry["retrieval"].items():
            table.add_row(
                f"sim {split}", str(r["queries"]),
                f"{r['all']['top1']:.2f} / {r['all']['top5']:.2f}",
                f"{r['same_class']['top1']:.2f} / {r['same_class']['top5']:.2f}",
            )  # fmt: skip
        real = entry.get("scan2cad")
        if real:
            table.add_row(
                "Scan2CAD", str(real["scan_segments"]),
                f"{real['all']['top1']:.2f} / {real['all']['top5']:.2f}",
                f"{real['same_class']['top1']:.2f} / {real['same_class']['top5']:.2f}",
            )  # fmt: skip
        console.print(table)
        calibration = entry.get("calibration")
        if calibration:
            console.print(f"δ({kind}) = {calibration['delta']:.2f}")
            for map_kind, m in calibration["maps"].items():
                gate = entry["gate"].get(map_kind, {})
                without, with_ = gate.get("without", {}), gate.get("with", {})
                console.print(
                    f"  {map_kind:14s} true pass {m['true_pass']:.3f}  wrong removed "
                    f"{m['wrong_removed']:.3f}  recall {without.get('recall', 0):.2f} -> "
                    f"{with_.get('recall', 0):.2f} ({with_.get('attempts', 0)} attempts)"
                )


def write_report(report: dict, out: str | Path) -> list[Path]:
    """descriptors_eval.json and a retrieval bar chart in `out`."""

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "descriptors_eval.json"]
    write_atomic(paths[0], json.dumps(report, indent=1, default=float) + "\n")
    paths.append(_figure(report, out / "descriptors_retrieval.png"))
    return paths


def _figure(report: dict, path: Path) -> Path:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    groups = []
    for kind, entry in report["kinds"].items():
        r = entry["retrieval"]["held_out"]
        groups.append((f"{kind}\nsim held-out", r))
        if entry.get("scan2cad"):
            groups.append((f"{kind}\nScan2CAD", entry["scan2cad"]))
    fig, ax = plt.subplots(figsize=(1.8 * len(groups) + 2, 3.2))
    width = 0.2
    metrics = [("all", "top1"), ("all", "top5"), ("same_class", "top1")]
    for k, (scope, top) in enumerate(metrics):
        values = [g[1][scope][top] for g in groups]
        ax.bar(np.arange(len(groups)) + (k - 1) * width, values, width, label=f"{scope} {top}")
    ax.set_xticks(np.arange(len(groups)), [g[0] for g in groups], fontsize=8)
    ax.set_ylim(0, 1.05)
    ax.set_ylabel("retrieval rate")
    ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path

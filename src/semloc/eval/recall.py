"""Metrics of `results.csv` (and `hypotheses.csv`): recall at top-k, recall vs translation
tolerance, a summary per method and map kind.  Pure functions of the rows, so exact and testable.

`results.csv`: method,map_kind,sequence,start,offset,n_local,rank_of_first_correct,rot_err_deg,
trans_err_m,ms (one row per attempt and method; rank empty when no hypothesis is within
15 deg / 0.5 m; errors those of the best hypothesis, empty when there is none).
`hypotheses.csv`: method,map_kind,sequence,start,offset,rank,rot_err_deg,trans_err_m (every
reported hypothesis), which makes the top-k recall at any translation tolerance exact.
"""

from __future__ import annotations

import csv
import io
from collections import defaultdict
from collections.abc import Iterable, Sequence
from pathlib import Path

import numpy as np

from semloc.eval.success import ROTATION_TOLERANCE_DEG

RESULT_COLUMNS = [
    "method", "map_kind", "sequence", "start", "offset", "n_local",
    "rank_of_first_correct", "rot_err_deg", "trans_err_m", "ms",
]  # fmt: skip
HYPOTHESIS_COLUMNS = [
    "method", "map_kind", "sequence", "start", "offset", "rank", "rot_err_deg", "trans_err_m",
]  # fmt: skip
_INT = {"start", "offset", "n_local", "rank_of_first_correct", "rank"}
_FLOAT = {"rot_err_deg", "trans_err_m", "ms"}


def _parse(row: dict[str, str]) -> dict:
    out: dict = {}
    for key, value in row.items():
        value = (value or "").strip()
        if key in _INT:
            out[key] = int(value) if value else None
        elif key in _FLOAT:
            out[key] = float(value) if value else None
        else:
            out[key] = value
    return out


def read_rows(path: str | Path, columns: Sequence[str] = RESULT_COLUMNS) -> list[dict]:
    """Rows of a results (or hypotheses) CSV; empty cells become None."""
    with open(path, newline="", encoding="utf-8") as handle:
        reader = csv.DictReader(handle)
        missing = [c for c in columns if c not in (reader.fieldnames or [])]
        if missing:
            raise ValueError(f"{path}: missing columns {missing}")
        return [_parse(row) for row in reader]


def format_rows(rows: Iterable[dict], columns: Sequence[str]) -> str:
    """CSV text of `rows` (None -> empty cell, floats with 4 decimals)."""
    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    writer.writerow(columns)
    for row in rows:
        cells = []
        for c in columns:
            v = row.get(c)
            cells.append("" if v is None else f"{v:.4f}" if isinstance(v, float) else str(v))
        writer.writerow(cells)
    return buffer.getvalue()


def group_by(rows: Iterable[dict], *keys: str) -> dict[tuple, list[dict]]:
    groups: dict[tuple, list[dict]] = defaultdict(list)
    for row in rows:
        groups[tuple(row[k] for k in keys)].append(row)
    return dict(groups)


def recall_at_k(rows: Sequence[dict], k: int) -> float:
    """Share of attempts whose first correct hypothesis has rank <= k (nan if no attempts)."""
    if not rows:
        return float("nan")
    return sum(1 for r in rows if r["rank_of_first_correct"] is not None
               and r["rank_of_first_correct"] <= k) / len(rows)  # fmt: skip


def recall_vs_tolerance(
    rows: Sequence[dict],
    tolerances: Sequence[float],
    hypotheses: Sequence[dict] | None = None,
    k: int = 10,
    rotation_deg: float = ROTATION_TOLERANCE_DEG,
) -> np.ndarray:
    """Recall at each translation tolerance (rotation < `rotation_deg`), within the top-k.

    With `hypotheses` (rows of hypotheses.csv) an attempt counts at tolerance t when one of its
    first k hypotheses is within rotation_deg and t; without, only the best hypothesis'
    errors of results.csv are known, which gives the top-1 curve.
    """
    if not rows:
        return np.full(len(tolerances), np.nan)
    best: dict[tuple, float] = {}
    key = ("method", "map_kind", "sequence", "start", "offset")
    if hypotheses is not None:
        for h in hypotheses:
            if h["rank"] <= k and h["rot_err_deg"] is not None and h["rot_err_deg"] < rotation_deg:
                kk = tuple(h[c] for c in key)
                best[kk] = min(best.get(kk, np.inf), h["trans_err_m"])
    else:
        for r in rows:
            if r["rot_err_deg"] is not None and r["rot_err_deg"] < rotation_deg:
                best[tuple(r[c] for c in key)] = r["trans_err_m"]
    errors = np.array([best.get(tuple(r[c] for c in key), np.inf) for r in rows])
    return np.array([float(np.mean(errors < t)) for t in tolerances])


def summary(rows: Sequence[dict], ks: Sequence[int] = (1, 10)) -> list[dict]:
    """Per (method, map kind): attempts, recall@k, median errors of successes, median ms."""
    out = []
    for (method, kind), group in sorted(group_by(rows, "method", "map_kind").items()):
        ok = [r for r in group if r["rank_of_first_correct"] == 1]
        ms = [r["ms"] for r in group if r["ms"] is not None]
        entry = {"method": method, "map_kind": kind, "attempts": len(group)}
        for k in ks:
            entry[f"recall@{k}"] = recall_at_k(group, k)
        entry["median_rot_err_deg"] = (
            float(np.median([r["rot_err_deg"] for r in ok])) if ok else None
        )
        entry["median_trans_err_m"] = (
            float(np.median([r["trans_err_m"] for r in ok])) if ok else None
        )
        entry["median_ms"] = float(np.median(ms)) if ms else None
        out.append(entry)
    return out

"""The JSON document of a localization answer: the one place that assembles it.

`semloc localize --format json`, the service's answers (`semloc serve`: one-shot localizations
and session updates) and the lines of `semloc bag localize --jsonl` are all
`answer_document(result, labels, ...)`: the result's own fields (`Result.to_dict`), then
`labels` (how each local label was read against the map's), then what the writer adds
(`warm_up_ms`, `ground_truth`, `map_version`, `stamp`, ...).  `answer_text` is its text as
every file writer writes it (indented, NaN and infinities refused).
"""

from __future__ import annotations

import json
from typing import Any

from semloc.association import LabelResolution, labels_json
from semloc.results import Result


def answer_document(
    result: Result,
    labels: dict[str, LabelResolution],
    last_steps: int | None = None,
    **extra: Any,
) -> dict[str, Any]:
    """The answer's JSON document: `result`'s fields, `labels`, then `extra` in its order.
    `last_steps`: keep only that many of the latest steps (a stream writes each update's step
    on its own line)."""
    document = result.to_dict()
    if last_steps is not None:
        document["steps"] = document["steps"][-last_steps:] if last_steps else []
    document["labels"] = labels_json(labels)
    document.update(extra)
    return document


def answer_text(document: dict[str, Any]) -> str:
    """The text of an answer document: indented JSON, NaN and infinities refused
    (`ValueError`), one newline at the end."""
    return json.dumps(document, indent=1, allow_nan=False) + "\n"

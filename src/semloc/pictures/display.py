"""How user text (ids, labels, names, titles, file names) is shown: shortened, printable and
escaped for rich markup and matplotlib mathtext, so that no string a user controls can break
or slow down a table, a picture or an error line."""

from __future__ import annotations

from rich.markup import escape

DISPLAY_LENGTH = 40
"""Longest label or id shown in tables and pictures (longer ones end with `…`)."""


def printable(text: object) -> str:
    """`text` as a string any terminal or file encoding can take (lone surrogates and control
    characters escaped)."""
    text = str(text).encode("utf-8", "backslashreplace").decode("utf-8")
    if text.isprintable():
        return text
    return "".join(c if c.isprintable() or c == " " else repr(c)[1:-1] for c in text)


def shorten(text: object, limit: int = DISPLAY_LENGTH) -> str:
    """`printable(text)` cut to `limit` characters (the last one `…` when cut)."""
    text = printable(text)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def for_rich(text: object, limit: int | None = DISPLAY_LENGTH) -> str:
    """User text for a rich console: shortened (unless `limit` is None) and markup escaped."""
    return escape(printable(text) if limit is None else shorten(text, limit))


def for_matplotlib(text: object, limit: int | None = DISPLAY_LENGTH) -> str:
    """User text for matplotlib: shortened and `$` escaped (no mathtext)."""
    shown = printable(text) if limit is None else shorten(text, limit)
    return shown.replace("$", r"\$")

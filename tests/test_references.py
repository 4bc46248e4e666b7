"""No reference to a document that is not in the repository: the relative links of every
Markdown file, and every Markdown document named in code, docs, the Makefile and CI (a path
under `docs/`, a path climbing out with `../`, or a capitalised name such as
`CONTRIBUTING.md`), resolve to a file of the checkout."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SKIP = {".git", ".venv", ".pytest_cache", ".ruff_cache", ".hypothesis", "__pycache__",
        "node_modules", "build", "dist", "demo_out", "bench_out", "mutants"}  # fmt: skip
TEXT = {".py", ".md", ".toml", ".txt", ".yml", ".yaml", ".cfg", ".json", ".sh"}
OUTPUTS = {"TABLE.md"}
"""Names of files the tools write (`--markdown TABLE.md`), not documents."""
LINK = re.compile(r"\]\(([^)\s]+)\)")
NAMED = re.compile(r"(?<![\w/.-])((?:\.\./|docs/)[\w./-]*\w\.md|[A-Z][A-Z_]+\.md)\b")


def text_files() -> list[Path]:
    found = [ROOT / "Makefile", ROOT / ".ci" / "run"]
    for path in sorted(ROOT.rglob("*")):
        parts = path.relative_to(ROOT).parts
        skipped = SKIP & set(parts) or any(part.endswith(".egg-info") for part in parts)
        if path.suffix in TEXT and path.is_file() and not skipped:
            found.append(path)
    return found


def in_repository(path: Path) -> bool:
    """Whether `path` is a file or folder of the checkout (`../shared/x` beside it is not)."""
    return path.exists() and path.resolve().is_relative_to(ROOT)


def missing_links(path: Path) -> list[str]:
    """Relative links of a Markdown file (`[text](target#anchor)`) that name no file."""
    targets = [m.split("#")[0] for m in LINK.findall(path.read_text())]
    return [t for t in targets if t and "://" not in t and not t.startswith("mailto:")
            and not in_repository(path.parent / t)]  # fmt: skip


def missing_documents(path: Path) -> list[str]:
    """Markdown documents a file names that are neither beside it, at the root nor in docs/."""
    names = set(NAMED.findall(path.read_text(errors="replace"))) - OUTPUTS
    places = (path.parent, ROOT, ROOT / "docs")
    return sorted(n for n in names if not any(in_repository(place / n) for place in places))


def test_every_markdown_link_names_a_file_of_the_repository():
    broken = {
        str(path.relative_to(ROOT)): missing
        for path in text_files()
        if path.suffix == ".md" and (missing := missing_links(path))
    }
    assert broken == {}


def test_every_named_document_is_in_the_repository():
    broken = {
        str(path.relative_to(ROOT)): missing
        for path in text_files()
        if (missing := missing_documents(path))
    }
    assert broken == {}


def test_a_reference_outside_the_repository_is_caught(tmp_path):
    gone = "DESIGN" + ".md"  # (spelled apart: this file is scanned too)
    page = tmp_path / "page.md"
    page.write_text(f"See ../shared/{gone}, [the design](../shared/{gone}) and {gone}.\n")
    assert missing_links(page) == [f"../shared/{gone}"]
    assert missing_documents(page) == [f"../shared/{gone}", gone]
    page.write_text("See [the format](format.md), CHANGELOG.md and docs/contracts.md.\n")
    assert missing_documents(page) == [] and missing_links(page) == ["format.md"]

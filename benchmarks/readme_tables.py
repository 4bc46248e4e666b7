"""Rerun the benchmarks behind the README's and the docs' result tables and rewrite them in place.

Each table of README.md and of the docs pages sits between `<!-- table: NAME -->` and
`<!-- /table -->`; this script runs the benchmark that makes it (each benchmark once, also when
it feeds several tables), takes the table from the benchmark's markdown output (some rows and
columns of it, or a table built from several of its tables: the README's headline) and writes
it back between the markers with the command that reproduces it, so the pages are current
after every change without hand-editing.  Everything: about 32 minutes on 2 cores.

    python benchmarks/readme_tables.py [--only real-layouts trust ...] [--dry-run]

The real-layout tables need the real data samples (`SEMLOC_DATA` or `../shared/data/real`);
without them those tables are left as they are and the script says so.
"""

from __future__ import annotations

import argparse
import re
import subprocess
import sys
import tempfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PYTHON = "python"  # as the README shows the commands; run with this interpreter


@dataclass(frozen=True)
class Job:
    """A benchmark run: its command as a user types it (`{out}`: where it writes markdown), and
    the markdown file it writes, relative to `{out}`'s folder."""

    command: str
    report: str = "table.md"

    def shown(self) -> str:
        """The command as the pages show it: without the markdown file it writes for us."""
        return self.command.replace(" --markdown {out}", "").replace(
            "--out {out}", "--out bench_full"
        )


Tables = list[list[list[str]]]
"""The markdown tables of a report, each as rows of cells (header first)."""


@dataclass(frozen=True)
class TableSpec:
    """Which table of a job's report goes into a page, and which of its rows and columns (or
    `build`: the table made from all of the report's tables)."""

    job: str
    index: int  # the index-th markdown table of the report
    keep_row: Callable[[dict[str, str]], bool] = lambda row: True
    columns: tuple[str, ...] = ()  # headers to keep, in order (empty: all)
    file: str = "README.md"  # the page that shows it, relative to the repository's root
    build: Callable[[Tables], list[list[str]]] | None = None


SIMULATED_KINDS = ("reconstruction", "cad", "dynamic")


def headline(tables: Tables) -> list[list[str]]:
    """The README's one table, from `semloc bench`'s report: semloc and the best peer (the
    other method with the best mean top-1 over the simulated map kinds): top-1 / top-10 per
    map kind, the `localized` claims over the attempts of those map kinds and the real pairs
    (right / wrong, precision; not the night queries, whose object-method rows repeat the
    reconstruction rows) and the median time per update."""
    recall, claims = tables[0], tables[1]
    rows = {row[0]: dict(zip(recall[0], row)) for row in recall[1:]}

    def mean_top1(method: str) -> float:
        return sum(float(rows[method][f"{k}: top-1 / top-10"].split("/")[0])
                   for k in SIMULATED_KINDS) / len(SIMULATED_KINDS)  # fmt: skip

    peers = [m for m in rows if not m.startswith("semloc")]
    if "semloc" not in rows or not peers:
        raise SystemExit("readme_tables: the bench report needs semloc and another method")
    best = max(peers, key=mean_top1)
    header = ["method", "top-1 / top-10: reconstruction · CAD · dynamic",
              "`localized` claims right / wrong", "precision", "median ms / update"]  # fmt: skip
    body = []
    for method, shown in (("semloc", "semloc"), (best, f"{best} (best peer)")):
        right = wrong = 0
        for row in claims[1:]:
            cells = dict(zip(claims[0], row))
            if cells["method"] == method and cells["map"] != "night":
                right, wrong = (
                    right + int(cells["claims right"]),
                    wrong + int(cells["claims wrong"]),
                )
        precision = f"{100 * right / (right + wrong):.1f}%" if right + wrong else "-"
        accuracy = " · ".join(rows[method][f"{k}: top-1 / top-10"] for k in SIMULATED_KINDS)
        body.append([shown, accuracy, f"{right} / {wrong}", precision,
                     rows[method]["median ms / update"]])  # fmt: skip
    return [header, *body]


JOBS = {
    "real": Job(
        "python benchmarks/real_layouts.py --crops 100 --variants 20 --seed 0 --markdown {out}"
    ),
    "buildings": Job("python benchmarks/accuracy_core.py --trials 40 --markdown {out}"),
    "speed": Job("PYTHONPATH=src python benchmarks/bench_speed.py --views 8 --markdown {out}"),
    "vocab": Job(
        "PYTHONPATH=src python benchmarks/vocabulary.py --views 20 --buildings 2 --markdown {out}"
    ),
    "changes": Job("python benchmarks/changes.py --views 40 --markdown {out}"),
    "calibration": Job(
        "PYTHONPATH=src python benchmarks/calibrate_confidence.py --sequences 3 --starts 4 "
        "--holdout-sequences 2 --markdown {out}"
    ),
    "align": Job(
        "PYTHONPATH=src python benchmarks/bench_align.py --trials 5 --clipper-cases 1 "
        "--clipper-budget 120 --clipper-memory 6144 --markdown {out}"
    ),
    "bench": Job(
        "semloc bench --methods semloc,clipper,random-walk,segmatch,fpfh-ransac,sift,semloc+geometric,"
        "semloc+voxnet --out {out}",
        report="report.md",
    ),
    "bench-learned": Job("semloc bench --methods svl,fcgf-dense --out {out}", report="report.md"),
}

TABLES = {
    "headline": TableSpec("bench", 0, build=headline),
    "buildings": TableSpec(
        "buildings", 0, lambda r: r["observed objects"] not in {"4", "6"}, file="docs/benchmark.md"
    ),
    "speed": TableSpec(
        "speed",
        0,
        lambda r: r["map"] not in {"building-1000", "building-3000"},
        columns=(
            "map",
            "objects",
            "map prepared once, ms",
            "localization ms (median / p90 / max)",
            "update ms (median / p90 / max)",
            "peak MB",
            "success",
        ),
        file="docs/benchmark.md",
    ),  # fmt: skip
    "variants": TableSpec("real", 1, file="docs/trust.md"),
    "crops": TableSpec("real", 0, file="docs/real_layouts.md"),
    "align": TableSpec("align", 0, file="docs/alignment.md"),
    "changes": TableSpec("changes", 0, file="docs/trust.md"),
    "real-use": TableSpec("calibration", 0, file="docs/trust.md"),
    "unchanged": TableSpec("changes", 1, file="docs/trust.md"),
    "vocabulary-all": TableSpec("vocab", 0, file="docs/vocabulary.md"),
    "recall": TableSpec("bench", 0, file="docs/benchmark.md"),
    "claims": TableSpec("bench", 1, file="docs/benchmark.md"),
    "learned-recall": TableSpec("bench-learned", 0, file="docs/benchmark.md"),
    "learned-claims": TableSpec("bench-learned", 1, file="docs/benchmark.md"),
}


def markdown_tables(text: str) -> list[list[list[str]]]:
    """The markdown tables of `text`, each as rows of cells (header first, no separator)."""
    tables: list[list[list[str]]] = []
    current: list[list[str]] = []
    for line in [*text.splitlines(), ""]:
        if line.startswith("|"):
            cells = [c.strip() for c in line.strip().strip("|").split("|")]
            if not all(re.fullmatch(r":?-+:?", c) for c in cells):
                current.append(cells)
        elif current:
            tables.append(current)
            current = []
    return tables


def select(table: list[list[str]], spec: TableSpec) -> list[list[str]]:
    """The rows `spec` keeps (header always) and its columns, in its order."""
    header, body = table[0], table[1:]
    rows = [row for row in body if spec.keep_row(dict(zip(header, row)))]
    if not spec.columns:
        return [header, *rows]
    missing = [c for c in spec.columns if c not in header]
    if missing:
        raise SystemExit(f"readme_tables: the report has no column {missing}")
    index = [header.index(c) for c in spec.columns]
    return [[row[i] for i in index] for row in [header, *rows]]


def as_markdown(rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(rows[0]) + " |", "|" + "---|" * len(rows[0])]
    return "\n".join([*lines, *("| " + " | ".join(r) + " |" for r in rows[1:])])


def replace_table(readme: str, name: str, body: str) -> str:
    """`readme` with the text between the markers of table `name` replaced by `body`."""
    pattern = re.compile(rf"(<!-- table: {re.escape(name)} -->\n).*?(<!-- /table -->)", re.S)
    if not pattern.search(readme):
        raise SystemExit(f"readme_tables: README has no markers for table {name!r}")
    return pattern.sub(lambda m: m.group(1) + body + "\n" + m.group(2), readme, count=1)


def run_job(job: Job, folder: Path) -> str | None:
    """Run the job (from the repository root) and return its markdown report, or None when
    it could not run (missing real data: exit status 2)."""
    out = folder / "out" if job.report != "table.md" else folder / "table.md"
    command = job.command.format(out=out)
    command = command.replace("python ", f"{sys.executable} ", 1)
    command = command.replace("semloc bench", f"{sys.executable} -m semloc bench", 1)
    print(f"$ {job.shown()}", file=sys.stderr)
    done = subprocess.run(command, shell=True, cwd=ROOT)
    if done.returncode == 2:
        return None
    if done.returncode != 0:
        raise SystemExit(f"readme_tables: {job.command} failed (exit {done.returncode})")
    report = out / job.report if job.report != "table.md" else out
    return report.read_text(encoding="utf-8")


def rewritten(readme: str, names: list[str], reports: dict[str, str | None]) -> str:
    for name in names:
        spec = TABLES[name]
        report = reports.get(spec.job)
        if report is None:
            print(
                f"readme_tables: {name} left as it was (its benchmark did not run)", file=sys.stderr
            )
            continue
        tables = markdown_tables(report)
        if len(tables) <= spec.index:
            raise SystemExit(f"readme_tables: the report of {spec.job} has no table {spec.index}")
        rows = spec.build(tables) if spec.build else select(tables[spec.index], spec)
        body = f"`{JOBS[spec.job].shown()}`\n\n" + as_markdown(rows)
        readme = replace_table(readme, name, body)
    return readme


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--only", nargs="+", choices=sorted(TABLES), help="these tables only")
    parser.add_argument("--root", type=Path, default=ROOT, help="the pages' repository root")
    parser.add_argument("--dry-run", action="store_true", help="print, do not rewrite")
    args = parser.parse_args(argv)
    names = args.only or list(TABLES)
    with tempfile.TemporaryDirectory() as tmp:
        reports = {}
        for job in dict.fromkeys(TABLES[n].job for n in names):
            folder = Path(tmp) / job
            folder.mkdir()
            reports[job] = run_job(JOBS[job], folder)
    for page in dict.fromkeys(TABLES[n].file for n in names):
        path = args.root / page
        mine = [n for n in names if TABLES[n].file == page]
        text = rewritten(path.read_text(encoding="utf-8"), mine, reports)
        if args.dry_run:
            print(text)
            continue
        partial = path.with_name(f".{path.name}.partial")
        partial.write_text(text, encoding="utf-8")
        partial.replace(path)
        print(f"rewrote {len(mine)} table(s) of {page}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())

"""A longer soak of the fuzz suite: many mutated dataset scenes through `semloc convert`, and
the hostile map cases, in-process; prints a table of outcomes (exit 0 / 1 / 2 / other).

    PYTHONPATH=src:tests:tests/fuzz python benchmarks/fuzz_soak.py --seeds 200
"""

from __future__ import annotations

import argparse
import contextlib
import io
import tempfile
import time
from collections import Counter
from pathlib import Path

from cases import MAP_CASES, SCENES, mutated_scene

from semloc.cli import main


def run(case) -> tuple[int, str]:
    with tempfile.TemporaryDirectory() as folder:
        argv, _ = case.setup(Path(folder))
        err = io.StringIO()
        with contextlib.redirect_stderr(err), contextlib.redirect_stdout(io.StringIO()):
            try:
                code = main(argv)
            except BaseException as exc:  # noqa: BLE001 (the soak reports everything)
                return -1, f"{type(exc).__name__}: {exc}"
        return code, err.getvalue()


def main_soak() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seeds", type=int, default=100, help="Mutations per dataset format.")
    args = parser.parse_args()
    cases = MAP_CASES + [mutated_scene(k, 1000 + s) for k in SCENES for s in range(args.seeds)]
    outcomes: Counter = Counter()
    bad = []
    begin = time.perf_counter()
    for case in cases:
        code, err = run(case)
        # 0 / 1 (update-map wrote nothing, not localized): warnings at most; 2: one error line
        quiet = all(line.startswith("warning: ") for line in err.splitlines())
        ok = "Traceback" not in err and (code in (0, 1) and quiet or code == 2 and not quiet)
        outcomes[(case.name.split("-mutated")[0].split("-")[0], code if ok else "BAD")] += 1
        if not ok:
            bad.append((case.name, code, err.strip()[:200]))
    print(f"{'group':<10} {'outcome':>8} {'runs':>6}")
    for (group, outcome), count in sorted(outcomes.items(), key=str):
        print(f"{group:<10} {outcome!s:>8} {count:>6}")
    print(f"{len(cases)} runs in {time.perf_counter() - begin:.0f} s; {len(bad)} bad")
    for name, code, err in bad:
        print(f"  {name}: {code} {err}")


if __name__ == "__main__":
    main_soak()

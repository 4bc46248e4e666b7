"""`semloc bench`: exact metrics from a hand-made results.csv, a reproducible tiny run, CLI errors."""

from __future__ import annotations

import math

import numpy as np
import pytest

from semloc.cli import main
from semloc.eval.recall import (
    HYPOTHESIS_COLUMNS,
    RESULT_COLUMNS,
    read_rows,
    recall_at_k,
    recall_vs_tolerance,
    summary,
)  # fmt: skip
from semloc.eval.report import attempt_tables, gamma_table, summary_table

RESULTS = """method,map_kind,sequence,start,offset,n_local,rank_of_first_correct,rot_err_deg,trans_err_m,ms
semloc,cad,seq0,3,0,3,1,2.0,0.10,10
semloc,cad,seq0,3,15,8,3,40.0,2.00,20
semloc,cad,seq0,3,30,12,,170.0,5.00,30
semloc,cad,seq1,7,0,4,1,1.0,0.30,40
clipper,cad,seq0,3,0,3,2,90.0,1.00,100
clipper,cad,seq0,3,15,8,,,,200
"""
HYPOTHESES = """method,map_kind,sequence,start,offset,rank,rot_err_deg,trans_err_m
semloc,cad,seq0,3,0,1,2.0,0.10
semloc,cad,seq0,3,15,1,40.0,2.00
semloc,cad,seq0,3,15,3,3.0,0.45
semloc,cad,seq0,3,15,12,1.0,0.05
semloc,cad,seq0,3,30,1,170.0,5.00
semloc,cad,seq1,7,0,1,1.0,0.30
semloc,cad,seq1,7,0,2,1.0,0.02
"""


@pytest.fixture()
def rows(tmp_path):
    (tmp_path / "results.csv").write_text(RESULTS)
    (tmp_path / "hypotheses.csv").write_text(HYPOTHESES)
    return (
        read_rows(tmp_path / "results.csv"),
        read_rows(tmp_path / "hypotheses.csv", HYPOTHESIS_COLUMNS),
    )


def test_recall_at_k_is_exact(rows):
    results, _ = rows
    semloc = [r for r in results if r["method"] == "semloc"]
    clipper = [r for r in results if r["method"] == "clipper"]
    assert recall_at_k(semloc, 1) == 0.5
    assert recall_at_k(semloc, 3) == 0.75
    assert recall_at_k(clipper, 1) == 0.0
    assert recall_at_k(clipper, 10) == 0.5
    assert math.isnan(recall_at_k([], 1))


def test_recall_vs_tolerance_is_exact(rows):
    results, hyps = rows
    semloc = [r for r in results if r["method"] == "semloc"]
    # top-10: attempt 1 at 0.10, attempt 2 at 0.45 (rank 12 is beyond k), 3 never, 4 at 0.02
    assert recall_vs_tolerance(semloc, [0.05, 0.2, 0.5, 10], hyps, k=10).tolist() == [
        0.25, 0.5, 0.75, 0.75,
    ]  # fmt: skip
    assert recall_vs_tolerance(semloc, [0.05, 0.2, 0.5], hyps, k=1).tolist() == [0, 0.25, 0.5]
    # without hypotheses.csv: the best hypothesis' errors of results.csv (top-1)
    assert recall_vs_tolerance(semloc, [0.2, 0.5]).tolist() == [0.25, 0.5]


def test_summary_is_exact(rows):
    results, _ = rows
    table = {(s["method"], s["map_kind"]): s for s in summary(results)}
    s = table[("semloc", "cad")]
    assert s["attempts"] == 4 and s["recall@1"] == 0.5 and s["recall@10"] == 0.75
    assert s["median_rot_err_deg"] == 1.5 and s["median_trans_err_m"] == pytest.approx(0.2)
    assert s["median_ms"] == 25.0
    assert table[("clipper", "cad")]["median_rot_err_deg"] is None


def test_missing_column_is_reported(tmp_path):
    (tmp_path / "bad.csv").write_text("method,map_kind\nsemloc,cad\n")
    with pytest.raises(ValueError, match="missing columns"):
        read_rows(tmp_path / "bad.csv")


@pytest.mark.slow
def test_tiny_run_is_reproducible(tmp_path):
    """The Dask run equals a serial recomputation (same seed) except for the times."""
    from semloc.eval.protocol import BenchConfig, run_attempts, simulate
    from semloc.eval.runner import plan, run_benchmark

    config = BenchConfig(
        sequences=1, size="tiny", keyframes=40, starts=1, map_kinds=["cad"],
        methods=["semloc", "clipper"], gammas=[0.8], ablation_starts=0, seed=3, real=False,
    )  # fmt: skip
    output = run_benchmark(config, tmp_path, workers=1, progress=False)
    header = (tmp_path / "results.csv").read_text().splitlines()[0]
    assert header == ",".join(RESULT_COLUMNS)
    for name in ("report.md", "comparison.png", "hypotheses.csv", "ablation_objects.png"):
        assert (tmp_path / name).exists()
    seq = simulate(config, 0)
    serial = []
    for attempt in plan(config, config.keyframes):
        serial += run_attempts(seq, attempt)[0]
    assert len(output.rows) == len(serial) == 6
    strip = [{k: v for k, v in r.items() if k != "ms"} for r in output.rows]
    assert strip == [{k: v for k, v in r.items() if k != "ms"} for r in serial]
    assert read_rows(tmp_path / "results.csv")[0]["offset"] == 0
    # rows carry the method's status (read by benchmarks/status_reliability.py), not the CSV
    assert {r["status"] for r in serial} <= {"localized", "ambiguous", "failed"}
    assert "status" not in (tmp_path / "results.csv").read_text().splitlines()[0]


@pytest.mark.parametrize(
    "argv",
    [
        ["bench", "--methods", "semloc,nope"],
        ["bench", "--workers", "0"],
        ["bench", "--scheduler", "tcp://127.0.0.1:1", "--workers", "2"],
        ["bench", "--starts", "abc"],
    ],
)
def test_bad_bench_input_exits_2_with_one_line(argv, capsys):
    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("semloc: error:") and "\n" not in err


@pytest.mark.parametrize("kind", ["geometric", "voxnet"])
def test_descriptor_variant_gates_with_calibrated_delta(kind):
    """`semloc+KIND` is the Localizer with descriptors of KIND on the global map."""
    from semloc.baselines import make_method
    from semloc.descriptors import DELTAS
    from semloc.localizer import Localizer
    from semloc.maps import ObjectMap, SemanticObject

    rng = np.random.default_rng(0)
    objects = [
        SemanticObject(f"c{i}", "chair", np.array([i, 0.0, 0.4]),
                       points=rng.uniform(-0.3, 0.3, (200, 3)) + [i, 0.0, 0.4])
        for i in range(4)
    ]  # fmt: skip
    settings = {"min_fitness": 0.0}
    method = make_method(f"semloc+{kind}", ObjectMap(objects, up=[0, 0, 1]), np.array([0, 0, 1]),
                         settings=settings)  # fmt: skip
    assert isinstance(method, Localizer)
    assert method.config.decision.min_fitness == 0.0
    assert method.config.association.descriptor == kind
    assert method.descriptor_gate == pytest.approx(DELTAS[kind])
    assert all(d is not None for d in method.global_map.descriptors)


def test_bench_accepts_descriptor_variants_only_by_name(capsys):
    assert main(["bench", "--methods", "semloc+fancy"]) == 2
    err = capsys.readouterr().err
    assert "semloc+geometric" in err and "semloc+voxnet" in err


def test_attempt_tables_are_exact(rows):
    results, _ = rows
    real = dict(results[0], map_kind="real", sequence="3rscan", rank_of_first_correct=None)
    dynamic = dict(results[4], map_kind="dynamic", rank_of_first_correct=1, n_local=5, ms=300)
    text = attempt_tables([*results, real, dynamic], ["semloc", "clipper", "fpfh-ransac"])
    by_attempt, per_kind = text.split("\nFirst attempt, top-1 per map kind:\n\n")
    assert by_attempt.splitlines() == [
        "| method | first (> 2 objects) | +15 keyframes | +30 keyframes |",
        "|---|---|---|---|",
        "| semloc | 1.00 (~4 objects, 25 ms) | 0.00 (~8 objects, 20 ms) | 0.00 (~12 objects, 30 ms) |",
        "| clipper | 0.50 (~4 objects, 200 ms) | 0.00 (~8 objects, 200 ms) | – |",
        "| fpfh-ransac | – | – | – |",
    ]  # fmt: skip
    assert per_kind.splitlines() == [
        "| method | cad | dynamic |",
        "|---|---|---|",
        "| semloc | 1.00 | – |",
        "| clipper | 0.00 | 1.00 |",
        "| fpfh-ransac | – | – |",
    ]


def test_summary_table_is_exact(rows):
    results, _ = rows
    assert summary_table(results, ["semloc", "clipper"]).splitlines() == [
        "| method | cad: top-1 / top-10 | median ms / update |",
        "|---|---|---|",
        "| semloc | 0.50 / 0.75 | 25 |",
        "| clipper | 0.00 / 0.50 | 150 |",
    ]


def test_gamma_table_is_exact(rows):
    results, _ = rows
    semloc = [r for r in results if r["method"] == "semloc"]
    ablation = [dict(r, method="semloc gamma=0.95") for r in semloc[:2]]
    ablation += [dict(r, method="semloc gamma=0.5") for r in semloc]
    assert gamma_table(ablation).splitlines() == [
        "| γ | attempts | top-1 | top-5 | top-10 | top-20 | median ms |",
        "|---|---|---|---|---|---|---|",
        "| 0.5 | 4 | 0.50 | 0.75 | 0.75 | 0.75 | 25 |",
        "| 0.95 | 2 | 0.50 | 1.00 | 1.00 | 1.00 | 15 |",
    ]


def test_plan_gives_ablation_chains_their_gamma_and_top_k():
    from semloc.eval.protocol import BenchConfig
    from semloc.eval.runner import plan

    config = BenchConfig(sequences=1, starts=1, ablation_starts=1, gammas=[0.5, 0.9],
                         methods=["semloc", "clipper"], map_kinds=["cad"])  # fmt: skip
    jobs = plan(config, 80)
    assert [(j.method, j.name, j.settings, j.ablation) for j in jobs] == [
        ("semloc", "semloc", {}, False),
        ("clipper", "clipper", {}, False),
        ("semloc", "semloc gamma=0.5", {"gamma": 0.5, "top_k": 20}, True),
        ("semloc", "semloc gamma=0.9", {"gamma": 0.9, "top_k": 20}, True),
    ]


def test_replays_are_shared_per_sequence_object_start_and_stop():
    from semloc.eval.protocol import replayed

    class Sequence:
        def __init__(self):
            self.calls = []

        def replay(self, start, stop):
            self.calls.append((start, stop))
            return object()

    a, b = Sequence(), Sequence()
    first = replayed(a, 3, 40)
    assert replayed(a, 3, 40) is first and a.calls == [(3, 40)]
    assert replayed(a, 4, 40) is not first and replayed(b, 3, 40) is not first
    assert a.calls == [(3, 40), (4, 40)] and b.calls == [(3, 40)]


def test_night_queries_are_run_for_image_methods_and_copied_for_object_methods():
    from semloc.eval.protocol import BenchConfig, bench_kinds, conditions, with_night_rows
    from semloc.eval.runner import plan

    config = BenchConfig(sequences=1, starts=1, ablation_starts=0, methods=["semloc", "sift"],
                         map_kinds=["cad", "reconstruction", "dynamic"])  # fmt: skip
    assert bench_kinds(config) == ["cad", "reconstruction", "night", "dynamic"]
    assert [(j.map_kind, j.method) for j in plan(config, 80) if j.map_kind == "night"] == [
        ("night", "sift")]  # fmt: skip
    rows = [{"method": "semloc", "map_kind": "reconstruction", "ms": 3.0},
            {"method": "semloc", "map_kind": "cad", "ms": 4.0},
            {"method": "sift", "map_kind": "reconstruction", "ms": 5.0},
            {"method": "sift", "map_kind": "night", "ms": 6.0}]  # fmt: skip
    assert with_night_rows(rows, "reconstruction", "night") == [
        *rows, {"method": "semloc", "map_kind": "night", "ms": 3.0}]  # fmt: skip
    assert conditions("night") == ("reconstruction", "night")
    assert conditions("cad") == ("cad", "day")
    assert bench_kinds(config.model_copy(update={"night": False})) == config.map_kinds
    assert "night" not in bench_kinds(config.model_copy(update={"map_kinds": ["cad"]}))


def test_image_methods_are_planned_on_the_real_scans_colours_not_on_cad_maps():
    from semloc.eval import realwalks
    from semloc.eval.protocol import BenchConfig

    config = BenchConfig(methods=["semloc", "sift"], real_walk_count=1, real_walk_starts=1)
    kinds = {(job[-1], job[3]) for job in realwalks.plan(config)}
    assert {k for m, k in kinds if m == "sift"} == {"reconstruction", "night"}
    assert {k for m, k in kinds if m == "semloc"} == {"reconstruction", "cad"}  # night: copied

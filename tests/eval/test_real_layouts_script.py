"""benchmarks/real_layouts.py stays runnable: its crop check and table on a generated map."""

from __future__ import annotations

import numpy as np
from helpers import benchmark_script

from semloc.maps import ObjectMap, SemanticObject


def _script():
    return benchmark_script("real_layouts")


def _room() -> ObjectMap:
    rng = np.random.default_rng(4)
    labels = ["chair", "table", "lamp", "sofa", "bin"]
    objects = []
    for i in range(15):
        centre = np.append(rng.uniform(0, 6, 2), rng.uniform(0.3, 1.5))
        objects.append(SemanticObject(id=str(i), label=labels[i % 5], position=centre,
                                      points=centre + rng.normal(0, 0.15, (30, 3))))  # fmt: skip
    return ObjectMap(objects, up=[0, 0, 1], name="room")


def test_crop_check_and_table():
    script = _script()
    trials = script.crop_trials("room crops", _room(), count=4, seed=0, radii=(2.5, 3.5))
    assert len(trials) == 4 and all(t.n_objects >= 1 for t in trials)
    identity = script.run_trial("room itself", _room(), _room(), np.eye(4))
    assert identity.top1 and identity.rotation_deg < 1e-6
    text = script.table([*trials, identity])
    assert text.startswith("| check | observed objects | runs | top-1 | top-10 |")
    assert "| room crops | all | 4 |" in text and "| room itself | 15 | 1 | 100% |" in text


def test_real_data_dir_resolution(monkeypatch, tmp_path):
    from semloc.eval.datasets import real_data_dir

    monkeypatch.setenv("SEMLOC_DATA", str(tmp_path))
    assert real_data_dir() == tmp_path
    monkeypatch.setenv("SEMLOC_DATA", str(tmp_path / "absent"))
    assert real_data_dir() is None


def test_script_without_data_exits_2(monkeypatch, tmp_path, capsys):
    monkeypatch.setenv("SEMLOC_DATA", str(tmp_path / "absent"))
    assert _script().main([]) == 2
    assert "SEMLOC_DATA" in capsys.readouterr().err

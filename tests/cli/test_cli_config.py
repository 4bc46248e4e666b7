"""`semloc --version`, `semloc config --dump` (JSON and YAML) and `--config` reading it back."""

from __future__ import annotations

import json

import pytest
import yaml

import semloc
from semloc.cli import main
from semloc.localizer import LocalizerConfig


def test_version(capsys):
    assert main(["--version"]) == 0
    assert capsys.readouterr().out.strip() == f"semloc {semloc.__version__}"


@pytest.mark.parametrize("form, parse", [("json", json.loads), ("yaml", yaml.safe_load)])
def test_dump_prints_every_default_setting(form, parse, capsys):
    assert main(["config", "--dump", "--format", form]) == 0
    data = parse(capsys.readouterr().out)
    assert data == LocalizerConfig().model_dump(mode="json")
    assert data["clustering"]["gamma"] == 0.8 and data["decision"]["min_pairs"] == 3


@pytest.mark.parametrize("suffix", [".json", ".yaml"])
def test_dump_round_trips_through_config(suffix, tmp_path, capsys):
    edited = tmp_path / f"edited{suffix}"
    assert main(["config", "--dump", "--format", suffix[1:], "-o", str(edited)]) == 0
    text = edited.read_text().replace("gamma: 0.8", "gamma: 0.7")
    text = text.replace('"gamma": 0.8', '"gamma": 0.7')
    edited.write_text(text)
    assert main(["config", "--dump", "--config", str(edited)]) == 0
    read_back = LocalizerConfig(**json.loads(capsys.readouterr().out))
    assert read_back == LocalizerConfig(gamma=0.7)


def test_bad_config_files_are_one_line(tmp_path, capsys):
    broken = tmp_path / "broken.yaml"
    broken.write_text("clustering: [gamma: 0.8\n")
    assert main(["config", "--dump", "--config", str(broken)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"semloc: error: {broken}: not valid YAML") and err.count("\n") == 1
    wrong = tmp_path / "wrong.yaml"
    wrong.write_text("gama: 0.8\n")
    assert main(["config", "--dump", "--config", str(wrong)]) == 2
    assert "invalid settings" in capsys.readouterr().err
    assert main(["config"]) == 2
    assert "--dump" in capsys.readouterr().err


def test_help_shows_defaults_plainly(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "200")  # one line per option
    assert main(["localize", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "[default: 0.8]" in text and "[default: 10]" in text
    assert "(0.8)" not in text

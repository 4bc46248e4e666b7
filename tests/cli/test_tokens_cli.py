"""`semloc tokens add | list | revoke`: the token file holds digests only, is written
atomically in its own format (JSON or YAML) and is read back by the server's own reader."""

from __future__ import annotations

import hashlib
import json

import pytest
import yaml

from semloc.cli import main

pytest.importorskip("fastapi", reason="the token file is the serve extra's")
from semloc.serve.access import Access  # noqa: E402


@pytest.mark.parametrize("name", ["tokens.json", "tokens.yaml"])
def test_add_list_revoke(tmp_path, capsys, name):
    path = tmp_path / name
    assert main(["tokens", "add", str(path), "--map", "office=read,localize", "--map", "*=read",
                 "--name", "robot-1"]) == 0  # fmt: skip
    out, err = capsys.readouterr()
    token = out.strip()
    assert len(token) >= 24 and "only its digest is stored" in err and "Restart" in err
    text = path.read_text()
    assert token not in text
    data = yaml.safe_load(text) if name.endswith(".yaml") else json.loads(text)
    [entry] = data["tokens"]
    assert entry == {"sha256": hashlib.sha256(token.encode()).hexdigest(),
                     "maps": {"office": ["read", "localize"], "*": ["read"]}, "name": "robot-1"}  # fmt: skip
    grant = Access.from_file(path).grant(token)  # the server reads it
    assert grant is not None and grant.rights("office") == {"read", "localize"}
    assert main(["tokens", "add", str(path), "--map", "lab=write"]) == 0
    second = capsys.readouterr().out.strip()
    assert main(["tokens", "list", str(path)]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].split("\t") == [
        "robot-1",
        entry["sha256"][:12],
        "office: read,localize; *: read",
    ]
    assert lines[1].startswith("-\t") and lines[1].endswith("lab: write")
    assert main(["tokens", "revoke", str(path), "robot-1"]) == 0
    assert "revoked robot-1" in capsys.readouterr().out
    access = Access.from_file(path)
    assert access.grant(token) is None and access.grant(second) is not None
    digest = hashlib.sha256(second.encode()).hexdigest()
    assert main(["tokens", "revoke", str(path), digest[:10]]) == 0
    assert Access.from_file(path).grant(second) is None


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["add", "{f}", "--map", "office"], "give MAP_ID=RIGHTS"),
        (["add", "{f}", "--map", "office=fly"], "unknown rights fly"),
        (["add", "{f}", "--map", "a=read", "--name", "taken"], "a token named 'taken' is there"),
        (["revoke", "{f}", "nobody"], "no token named 'nobody'"),
        (["list", "{bad}"], "not valid JSON/YAML"),
        (["revoke", "{missing}", "x"], "cannot read the token file"),
    ],
)
def test_bad_input_is_one_line_and_status_2_and_the_file_stays(tmp_path, capsys, argv, message):
    path, bad = tmp_path / "t.json", tmp_path / "bad.json"
    assert main(["tokens", "add", str(path), "--map", "a=read", "--name", "taken"]) == 0
    before = path.read_text()
    bad.write_text("{not json")
    capsys.readouterr()
    args = [a.format(f=path, bad=bad, missing=tmp_path / "none.json") for a in argv]
    assert main(["tokens", *args]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("semloc: error: ") and message in err, err
    assert path.read_text() == before

"""`semloc maps put | get | list | versions` against a live server, and the rights each needs:
`put` write, the others read (a write-only token uploads but does not list or read)."""

from __future__ import annotations

import json

import pytest

from semloc.cli import main
from semloc.io import load_map, save_map
from semloc.serve.access import Access

ALL, WRITE_ONLY, READ_ONLY = "all-rights-token", "write-only-token", "read-only-token"


@pytest.fixture
def hub(serve, tmp_path):
    tokens = tmp_path / "tokens.json"
    tokens.write_text(json.dumps({"tokens": [
        {"token": ALL, "maps": {"*": ["read", "localize", "write"]}},
        {"token": WRITE_ONLY, "maps": {"*": ["write"]}},
        {"token": READ_ONLY, "maps": {"*": ["read"]}},
    ]}))  # fmt: skip
    return serve(access=Access.from_file(tokens)).url


def _maps(url: str, token: str, *args: str) -> int:
    return main(["maps", *args, "--server", url, "--token", token])


def test_put_get_list_versions(hub, building, tmp_path, capsys):
    source = save_map(building, tmp_path / "office.json")
    assert _maps(hub, ALL, "put", "office", str(source)) == 0
    assert _maps(hub, ALL, "put", "office", str(source)) == 0
    out = capsys.readouterr().out
    assert "office: version 1 (40 objects)" in out and "office: version 2" in out
    assert _maps(hub, READ_ONLY, "list") == 0
    assert "office\tversion 2" in capsys.readouterr().out
    assert _maps(hub, READ_ONLY, "versions", "office") == 0
    lines = capsys.readouterr().out.splitlines()
    assert [line.split("\t")[0] for line in lines] == ["1", "2"] and "upload" in lines[0]
    got = tmp_path / "got.json"
    assert _maps(hub, READ_ONLY, "get", "office", "-o", str(got), "--version", "1") == 0
    assert "wrote" in capsys.readouterr().out
    fetched = load_map(got)
    assert fetched.ids.tolist() == building.ids.tolist()
    assert abs(fetched.positions - building.positions).max() < 1e-5


def test_a_write_only_token_uploads_but_neither_lists_nor_reads(hub, building, tmp_path, capsys):
    source = save_map(building, tmp_path / "office.json")
    assert _maps(hub, WRITE_ONLY, "put", "office", str(source)) == 0
    assert "version 1" in capsys.readouterr().out
    assert _maps(hub, WRITE_ONLY, "list") == 0  # listing shows the maps the token may read
    assert "no maps this token may read" in capsys.readouterr().out
    assert _maps(hub, WRITE_ONLY, "get", "office", "-o", str(tmp_path / "x.json")) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "403 forbidden" in err[0] and "may not read" in err[0]
    assert not (tmp_path / "x.json").exists()


def test_refusals_are_one_line_and_status_2(hub, building, tmp_path, capsys):
    source = save_map(building, tmp_path / "office.json")
    assert _maps(hub, READ_ONLY, "put", "office", str(source)) == 2  # read is not write
    assert _maps(hub, "not-a-token-at-all", "list") == 2
    assert _maps(hub, ALL, "versions", "nowhere") == 2
    assert main(["maps", "list", "--server", "ftp://x"]) == 2
    assert _maps(hub, ALL, "put", "office", str(tmp_path / "missing.json")) == 2
    errors = capsys.readouterr().err.strip().splitlines()
    assert len(errors) == 5 and all(e.startswith("semloc: error: ") for e in errors), errors
    assert "403" in errors[0] and "401" in errors[1] and "404" in errors[2]

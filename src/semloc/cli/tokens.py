"""`semloc tokens add | list | revoke`: the token file of `semloc serve --tokens FILE`.

The file is JSON, or YAML for .yaml / .yml: `{"tokens": [{"sha256": ..., "maps": {MAP_ID | "*":
[rights]}, "name": ...}]}`.  `add` makes a new random token, prints it once and stores only its
SHA-256 digest; `revoke` removes a token by its name or the start of its digest.  The file is
checked as the server reads it before anything changes, and written atomically.  A running
server reads the file when it starts: restart it to apply a change.
"""

from __future__ import annotations

import hashlib
import json
import secrets
from pathlib import Path
from typing import Annotated, Any

import typer
import yaml

from semloc.cli.app import app, exit_statuses, fail
from semloc.cli.extras import need
from semloc.io import write_atomic

RIGHTS = ("read", "localize", "write")
"""The rights of a token on a map (as `semloc.serve.access` reads them)."""

tokens_app = typer.Typer(
    name="tokens",
    help="The token file of `semloc serve --tokens`: add, list, revoke (digests only).",
    no_args_is_help=True,
)
app.add_typer(tokens_app)

FileArgument = Annotated[
    Path, typer.Argument(help="The token file (JSON, or YAML for .yaml / .yml).")
]


def _is_yaml(path: Path) -> bool:
    return path.suffix.lower() in (".yaml", ".yml")


def read_tokens(path: Path, missing_ok: bool = False) -> list[dict[str, Any]]:
    """The entries of a token file, checked as the server checks them (one line, exit 2)."""
    need("tokens", "serve")
    if missing_ok and not path.exists():
        return []
    from semloc.serve.access import Access, TokenFileError  # checks as `semloc serve` does

    try:
        Access.from_file(path)
    except TokenFileError as exc:
        fail(str(exc))
    text = path.read_text(encoding="utf-8")
    data = yaml.safe_load(text) if _is_yaml(path) else json.loads(text)
    return list(data["tokens"])


def write_tokens(path: Path, entries: list[dict[str, Any]]) -> None:
    """Write the entries, atomically, in the file's format."""
    data = {"tokens": entries}
    if _is_yaml(path):
        text = yaml.safe_dump(data, sort_keys=False)
    else:
        text = json.dumps(data, indent=1) + "\n"
    write_atomic(path, text)


def parse_grant(text: str) -> tuple[str, list[str]]:
    """`office=read,localize` -> ("office", ["read", "localize"]) (one line, exit 2)."""
    map_id, equals, rights = text.partition("=")
    chosen = [r.strip() for r in rights.split(",") if r.strip()]
    if not equals or not map_id.strip() or not chosen:
        fail(f"--map {text!r}: give MAP_ID=RIGHTS, e.g. office=read,localize or '*=read'")
    unknown = [r for r in chosen if r not in RIGHTS]
    if unknown:
        fail(f"--map {text!r}: unknown rights {', '.join(unknown)} (known: {', '.join(RIGHTS)})")
    return map_id.strip(), list(dict.fromkeys(chosen))


def _digest(entry: dict[str, Any]) -> str:
    if "sha256" in entry:
        return str(entry["sha256"]).lower()
    return hashlib.sha256(str(entry["token"]).encode()).hexdigest()


@tokens_app.command(epilog=exit_statuses())
def add(
    file: FileArgument,
    grants: Annotated[
        list[str],
        typer.Option(
            "--map",
            help="MAP_ID=RIGHTS, rights among read, localize, write (e.g. office=read,localize, "
            "'*=read' for every map); repeat for several maps.",
        ),
    ],
    name: Annotated[
        str | None, typer.Option(help="A name to list and revoke it by (e.g. the device).")
    ] = None,
) -> None:
    """Make a new token with these rights: its digest goes into FILE (created if missing),
    the token itself is printed once, on stdout."""
    entries = read_tokens(file, missing_ok=True)
    if name is not None and any(e.get("name") == name for e in entries):
        fail(f"{file}: a token named {name!r} is there already (revoke it first)")
    maps = dict(parse_grant(text) for text in grants)
    token = secrets.token_urlsafe(24)
    entry: dict[str, Any] = {"sha256": hashlib.sha256(token.encode()).hexdigest(), "maps": maps}
    if name is not None:
        entry["name"] = name
    write_tokens(file, [*entries, entry])
    typer.echo(token)
    rights = "; ".join(f"{m}: {', '.join(r)}" for m, r in maps.items())
    typer.echo(
        f"added to {file} ({name or entry['sha256'][:12]}; {rights}); only its digest is "
        "stored: keep the token now. Restart semloc serve to apply.",
        err=True,
    )


@tokens_app.command(name="list", epilog=exit_statuses())
def list_tokens(file: FileArgument) -> None:
    """One line per token: name, start of its digest, rights per map (tab-separated)."""
    for entry in read_tokens(file):
        maps = "; ".join(f"{m}: {','.join(r)}" for m, r in entry["maps"].items())
        kind = "" if "sha256" in entry else " (plain token in the file)"
        typer.echo(f"{entry.get('name', '-')}\t{_digest(entry)[:12]}{kind}\t{maps}")


@tokens_app.command(epilog=exit_statuses())
def revoke(
    file: FileArgument,
    which: Annotated[
        str, typer.Argument(help="The token's name, or the start of its digest (8+ digits).")
    ],
) -> None:
    """Remove one token from FILE (by name or digest); restart semloc serve to apply."""
    entries = read_tokens(file)
    by_digest = len(which) >= 8 and all(c in "0123456789abcdef" for c in which.lower())
    found = [
        e
        for e in entries
        if e.get("name") == which or (by_digest and _digest(e).startswith(which.lower()))
    ]
    if not found:
        fail(f"{file}: no token named {which!r} or with a digest starting so")
    if len(found) > 1:
        fail(f"{file}: {len(found)} tokens match {which!r}: give more of the digest")
    write_tokens(file, [e for e in entries if e is not found[0]])
    typer.echo(f"revoked {which} in {file} ({len(entries) - 1} tokens left); restart semloc serve")

"""`semloc config`: print the full LocalizerConfig (defaults, or a `--config` file's) to edit."""

from __future__ import annotations

import json
from enum import StrEnum
from pathlib import Path
from typing import Annotated

import typer
import yaml
from pydantic import ValidationError

from semloc.cli.app import app, fail, first_error
from semloc.cli.files import check_separate, emit, read_config
from semloc.localizer import LocalizerConfig


class ConfigFormat(StrEnum):
    json = "json"
    yaml = "yaml"


def dump_config(config: LocalizerConfig, form: ConfigFormat) -> str:
    """Every setting of `config`, nested by stage, as JSON or YAML text that `--config` reads."""
    data = config.model_dump(mode="json")
    if form is ConfigFormat.yaml:
        return yaml.safe_dump(data, sort_keys=False, default_flow_style=False)
    return json.dumps(data, indent=2) + "\n"


@app.command()
def config(
    dump: Annotated[
        bool, typer.Option("--dump", help="Print every setting of the localizer.")
    ] = False,
    output_format: Annotated[
        ConfigFormat, typer.Option("--format", help="JSON or YAML (both are read by --config).")
    ] = ConfigFormat.json,
    config_file: Annotated[
        Path | None,
        typer.Option(
            "--config", help="Start from this settings file (JSON or .yaml) instead of defaults."
        ),
    ] = None,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write to this file.")
    ] = None,
) -> None:
    """The localizer's settings: `semloc config --dump > my.json`, edit, `localize --config my.json`.

    Settings may be nested by stage (association, clustering, pose, decision) as printed,
    or flat (`{"gamma": 0.7}`); a file given to --config needs only the settings it changes.
    """
    if not dump:
        fail("say what to do: --dump prints the settings (see semloc config --help)")
    check_separate({"--output": output}, {config_file: "the --config file"})
    try:
        settings = LocalizerConfig(**read_config(config_file))
    except ValidationError as exc:
        fail(f"{config_file}: invalid settings: {first_error(exc)}")
    text = dump_config(settings, output_format)
    emit(text, output)

"""`semloc.io` is split by concern (native map format, reading, output, interrupts):
each name lives in its home module only, and `semloc.io` offers the package's own API."""

from __future__ import annotations

import importlib

import pytest

import semloc.io
import semloc.io.native

PACKAGE_API = ["read_json", "load_map", "map_from_dict", "map_to_dict", "save_map",
               "write_atomic", "write_files", "map_files", "read_regular", "staged_folder",
               "load_scannet", "load_scan2cad", "load_replica", "load_rscan"]  # fmt: skip
HOMES = {"reading": ["read_json", "read_regular", "parse_json", "npy_header", "read_npy",
                     "check_regular", "require_keys", "MAX_JSON_BYTES", "MAX_FILE_BYTES"],
         "output": ["write_files", "write_atomic", "staged_folder"],
         "interrupts": ["Interrupted", "interrupts_raise", "interrupts_deferred",
                        "interrupts_wait", "signals_held", "children_spared",
                        "ignore_sigint"]}  # fmt: skip


def test_the_package_api_is_importable():
    assert [name for name in PACKAGE_API if not hasattr(semloc.io, name)] == []


@pytest.mark.parametrize("home", sorted(HOMES))
def test_a_name_lives_in_its_home_module_only(home):
    """The native map module re-exports nothing of the other concerns (what it imports, it
    uses: ruff's F401 checks that)."""
    module = importlib.import_module(f"semloc.io.{home}")
    assert module.__doc__
    for name in HOMES[home]:
        assert hasattr(module, name)
        assert name not in semloc.io.native.__all__, f"semloc.io.native re-exports {name}"


def test_the_native_module_exports_the_map_format_only():
    assert set(semloc.io.native.__all__) == {
        "BINARY_HINTS", "EMBEDDING_MEMBER", "FORMAT", "KIND_HINTS", "VERSION", "document_kind",
        "load_map", "map_files", "map_from_dict", "map_to_dict", "points_path", "save_map",
    }  # fmt: skip

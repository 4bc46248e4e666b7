"""`semloc.io` is split by concern (native map format, reading, output, interrupts), and every
name that `semloc.io` and `semloc.io.native` offered before the split is still there: other
code imports them."""

from __future__ import annotations

import importlib

import pytest

import semloc.io
import semloc.io.native

BEFORE_THE_SPLIT = {
    "semloc.io": ["read_json", "load_map", "map_from_dict", "map_to_dict", "save_map",
                  "write_atomic", "write_files", "map_files", "read_regular", "staged_folder",
                  "load_scannet", "load_scan2cad", "load_replica", "load_rscan"],
    "semloc.io.native": ["FORMAT", "VERSION", "EMBEDDING_MEMBER", "MAX_JSON_BYTES",
                         "MAX_FILE_BYTES", "BINARY_HINTS", "KIND_HINTS", "load_map",
                         "document_kind", "check_regular", "read_regular", "read_json",
                         "parse_json", "map_from_dict", "npy_header", "read_npy", "map_to_dict",
                         "points_path", "map_files", "save_map", "require_keys", "write_atomic",
                         "write_files", "interrupts_deferred", "interrupts_wait", "signals_held",
                         "staged_folder"],
}  # fmt: skip
HOMES = {"reading": ["read_json", "read_regular", "parse_json", "npy_header", "read_npy",
                     "check_regular", "require_keys", "MAX_JSON_BYTES", "MAX_FILE_BYTES"],
         "output": ["write_files", "write_atomic", "staged_folder"],
         "interrupts": ["interrupts_deferred", "interrupts_wait", "signals_held"]}  # fmt: skip


@pytest.mark.parametrize("module", sorted(BEFORE_THE_SPLIT))
def test_every_name_of_before_the_split_is_importable(module):
    loaded = importlib.import_module(module)
    missing = [name for name in BEFORE_THE_SPLIT[module] if not hasattr(loaded, name)]
    assert missing == []


@pytest.mark.parametrize("home", sorted(HOMES))
def test_a_moved_name_is_its_home_module_s_own(home):
    module = importlib.import_module(f"semloc.io.{home}")
    assert module.__doc__
    for name in HOMES[home]:
        assert getattr(semloc.io.native, name) is getattr(module, name)

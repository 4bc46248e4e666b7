"""Options and choices shared by several commands, built from the registries."""

from __future__ import annotations

from typing import Annotated

import typer

from semloc.association import DESCRIBERS
from semloc.cli.app import choices, fail
from semloc.descriptors import described
from semloc.maps import ObjectMap
from semloc.sim.mapkinds import MAP_KINDS
from semloc.sim.sensor import check_resolution
from semloc.sim.trajectory import PATHS
from semloc.sim.world import SIZES

DescriptorKind = choices("DescriptorKind", DESCRIBERS)
MapKindChoice = choices("MapKindChoice", MAP_KINDS)
PathChoice = choices("PathChoice", PATHS)

DescribeOption = Annotated[
    DescriptorKind | None,
    typer.Option(
        "--descriptor",
        help="Store shape descriptors of this kind for objects with points.",
    ),
]

SIZE_HELP = (
    "World size: "
    + ", ".join(f"{name} ({rooms} room{'s' if rooms > 1 else ''})" for name, rooms in SIZES.items())
    + ", or a room count."
)
RESOLUTION_HELP = "Depth image resolution WIDTHxHEIGHT (ScanNet intrinsics scaled)."


def with_descriptors(objmap: ObjectMap, kind: DescriptorKind | None) -> ObjectMap:
    """The map with descriptors of `kind` for its objects with points (unchanged for None)."""
    return described(objmap, None if kind is None else kind.value)


def parse_resolution(text: str) -> tuple[int, int]:
    """WIDTHxHEIGHT as two integers within the simulator's range, or one line + exit 2."""
    try:
        width, height = (int(v) for v in text.lower().split("x"))
    except ValueError:
        fail(f"--resolution must look like 240x180, got {text!r}")
    try:
        return check_resolution(width, height)
    except ValueError as exc:
        fail(str(exc))
        raise  # unreachable: fail() raises

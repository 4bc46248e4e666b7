"""Options and choices shared by several commands, built from the registries."""

from __future__ import annotations

from typing import Annotated

import typer

from semloc.association import DESCRIBERS
from semloc.cli.app import choices, fail
from semloc.cli.files import check_finite
from semloc.descriptors import described
from semloc.maps import ObjectMap
from semloc.priors import Prior
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


NearOption = Annotated[
    tuple[float, float, float] | None,
    typer.Option(
        "--near",
        help="Position prior: the local frame's origin lies near X Y Z (global frame, m); "
        "with --radius.",
    ),
]
RadiusOption = Annotated[
    float | None,
    typer.Option(help="Position prior: within this many metres of --near (> 0)."),
]


def prior_option(near: tuple[float, float, float] | None, radius: float | None) -> Prior | None:
    """The position prior of `--near X Y Z --radius R` (both or neither; one line, exit 2):
    the one reading of these options, for `localize`, `bag localize` and `ros2 node`."""
    if near is None and radius is None:
        return None
    if near is None or radius is None:
        fail("--near X Y Z and --radius R go together (a position prior needs both)")
    check_finite(near=near, radius=radius)
    try:
        return Prior(position=near, radius=radius)
    except ValueError as exc:
        fail(f"--near/--radius: {exc}")
        raise  # unreachable: fail() raises


def topic_option(name: str) -> str | None:
    """A topic option's value: None for 'none' (any case), for `bag localize` and `ros2 node`."""
    return None if name.lower() == "none" else name


CameraRangeOption = Annotated[
    float,
    typer.Option(
        "--range",
        min=0.1,
        max=1000.0,
        help="How far (m) the detector finds objects reliably (with --camera-info).",
    ),
]

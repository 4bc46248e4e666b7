"""Synthetic indoor worlds, an RGB-D sensor by ray casting (depth, instances and colour),
detection noise, illumination (day / night) and map variants.

from semloc.sim import generate_world, simulate_sequence
seq = simulate_sequence(seed=0, size="small", map_kinds="all", path="walk")
"""

from semloc.sim.colour import ColourSensor, map_keyframes
from semloc.sim.illumination import ILLUMINATIONS, Illumination, relight
from semloc.sim.mapkinds import MAP_KINDS, cad_map, dynamic_map, reconstruction_map
from semloc.sim.noise import DetectionNoise
from semloc.sim.scenario import Keyframe, SimulatedSequence, simulate_sequence
from semloc.sim.sensor import DepthSensor, Intrinsics
from semloc.sim.world import SIZES, World, generate_world

__all__ = [
    "ILLUMINATIONS",
    "MAP_KINDS",
    "SIZES",
    "ColourSensor",
    "DepthSensor",
    "DetectionNoise",
    "Illumination",
    "Intrinsics",
    "Keyframe",
    "SimulatedSequence",
    "World",
    "cad_map",
    "dynamic_map",
    "generate_world",
    "map_keyframes",
    "reconstruction_map",
    "relight",
    "simulate_sequence",
]

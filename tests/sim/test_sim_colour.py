"""Colour rendering of the simulated worlds: procedural textures and the day / night model."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from semloc.frontend.frames import RGBDFrame
from semloc.sim.illumination import DAY, ILLUMINATIONS, NIGHT, relight
from semloc.sim.textures import lattice_values, texture_for, tile_noise, value_noise

cells = st.lists(st.tuples(*[st.integers(-(10**6), 10**6)] * 3), min_size=1, max_size=20)
coords = st.floats(-50, 50, allow_nan=False)


@given(cells, st.integers(0, 2**32 - 1))
def test_lattice_values_are_deterministic_and_in_unit_interval(cs, seed):
    a = lattice_values(np.array(cs), seed)
    assert np.array_equal(a, lattice_values(np.array(cs), seed))
    assert a.shape == (len(cs), 3) and np.all((a >= 0) & (a < 1))


@given(st.tuples(coords, coords, coords), st.integers(0, 1000))
@settings(max_examples=60)
def test_value_noise_is_continuous_and_tiles_are_constant_per_cell(p, seed):
    p = np.array([p])
    near = p + 1e-6
    assert np.allclose(value_noise(p, 0.2, seed), value_noise(near, 0.2, seed), atol=1e-4)
    centre = (np.floor(p / 0.1) + 0.5) * 0.1  # inside the same tile as any point of the cell
    assert np.array_equal(tile_noise(centre, 0.1, seed), tile_noise(centre + 0.04, 0.1, seed))


def test_textures_are_deterministic_per_key_and_differ_between_keys():
    points = np.random.default_rng(0).uniform(-2, 2, (500, 3))
    a, b = texture_for("chair/1"), texture_for("chair/1")
    assert a == b and np.array_equal(a.colour(points), b.colour(points))
    other = texture_for("table/0").colour(points)
    assert np.abs(other - a.colour(points)).mean() > 0.05
    colours = a.colour(points)
    assert colours.min() >= 0 and colours.max() <= 1 and colours.std(axis=0).min() > 0.03


def _frame(seed: int = 0) -> RGBDFrame:
    rng = np.random.default_rng(seed)
    rgb = rng.integers(40, 230, (24, 32, 3), dtype=np.uint8)
    depth = rng.uniform(0.5, 5.0, (24, 32)).astype(np.float32)
    K = np.array([[30.0, 0, 16], [0, 30.0, 12], [0, 0, 1]])
    return RGBDFrame(0, rgb, depth, K, np.eye(4))


def test_night_is_deterministic_darker_and_warmer_and_keeps_depth():
    frame = _frame()
    a = relight(frame, NIGHT, np.random.default_rng(5))
    b = relight(frame, NIGHT, np.random.default_rng(5))
    assert np.array_equal(a.rgb, b.rgb) and a.rgb.dtype == np.uint8
    c = relight(frame, NIGHT, np.random.default_rng(6))
    assert not np.array_equal(a.rgb, c.rgb)  # sensor noise: another seed, other pixels
    assert a.rgb.mean() < 0.35 * frame.rgb.mean()
    red, blue = a.rgb[..., 0].astype(float).mean(), a.rgb[..., 2].astype(float).mean()
    assert blue < 0.7 * red  # tungsten light: blue cut more than red
    assert np.array_equal(a.depth, frame.depth)


def test_day_is_the_identity_and_the_registry_names_both():
    frame = _frame()
    assert relight(frame, DAY, np.random.default_rng(0)) is frame
    assert set(ILLUMINATIONS) == {"day", "night"}


def test_colour_rendering_is_deterministic_and_textured():
    pytest.importorskip("open3d")
    from semloc.sim.colour import ColourSensor, map_keyframes
    from semloc.sim.mapkinds import map_world, scan_poses
    from semloc.sim.sensor import Intrinsics
    from semloc.sim.world import generate_world

    world = generate_world(1, "tiny")
    K = Intrinsics.scannet(80, 60)
    T = scan_poses(world)[0]
    a = ColourSensor(world, K).render(T, 0, np.random.default_rng(1))
    b = ColourSensor(world, K).render(T, 0, np.random.default_rng(1))
    assert np.array_equal(a.rgb, b.rgb) and np.array_equal(a.depth, b.depth)
    hit = a.depth > 0
    assert hit.mean() > 0.5 and a.rgb[hit].std() > 10  # textured, not flat
    assert np.all(a.rgb[~hit] == 0)
    cad = ColourSensor(map_world(world, "cad"), K).render(T, 0)
    assert not np.array_equal(cad.rgb, a.rgb)  # other models, other textures
    kmap = map_keyframes(world, "reconstruction", resolution=(40, 30))
    assert len(kmap) == len(scan_poses(world)) and kmap.up.tolist() == [0, 0, 1]

"""Pixel tiles of the render kernels: few sizes, little padding, and no effect on the image."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gonio.brdf.models import Lambert, TorranceSparrow
from gonio.render import integrator, tiling
from gonio.render.lights import Environment
from gonio.render.scene import intersect_sphere


@pytest.mark.parametrize("cap", [8192, 2048, 1000, 300, 256, 40])
def test_sample_tiles_are_few_sizes_with_little_padding(cap):
    sizes = set()
    step = max(tiling.MIN_PIXEL_TILE, cap // tiling.TILE_SIZES)
    for n in range(1, 12 * cap + 2):
        tile = tiling.sample_tile(n, cap)
        sizes.add(tile)
        tiles = math.ceil(n / tile)
        assert tile <= cap, (n, tile)
        if n > tiling.MIN_PIXEL_TILE and cap > tiling.MIN_PIXEL_TILE:
            assert tiles == math.ceil(n / cap), (n, tile)  # as few kernel calls as the cap allows
            assert tile * tiles - n < step * tiles, (n, tile)  # under one step of padding a tile
            assert tile % step == 0 or tile == cap, (n, tile)
    # at most TILE_SIZES sizes per cap, plus one for tiny images
    assert len(sizes) <= tiling.TILE_SIZES + 1, sorted(sizes)


def test_a_128_sphere_is_padded_by_3_percent_not_21():
    n = 12868  # pixels of a 128² sphere
    cap = integrator.DEFAULT_TILE_SAMPLES // integrator.SAMPLE_BATCH
    assert tiling.sample_tile(n, cap) == 6656
    assert tiling.pixel_tile(n, cap) == 8192  # the delta lights' rule (and the old one)


@pytest.mark.parametrize(
    "material",
    [Lambert(albedo=[0.6, 0.5, 0.4]), TorranceSparrow(alpha=0.3, distribution="ggx")],
    ids=["lambert", "ggx"],
)
def test_tiles_only_group_pixels(monkeypatch, material):
    # The tile rule changes which pixels share a kernel call and how many padding pixels ride
    # along, never a pixel's samples: the image is the same, bit for bit.
    rng = np.random.default_rng(5)
    env = Environment(rng.random((8, 16, 3)).astype(np.float32))
    kw = {"resolution": 40, "spp": 5, "seed": 3, "tile_samples": 16 * 1024}
    equal = integrator.render_sphere(material, [env], **kw)
    monkeypatch.setattr(integrator, "sample_tile", tiling.pixel_tile)
    powers = integrator.render_sphere(material, [env], **kw)
    n = intersect_sphere(40).count
    assert tiling.sample_tile(n, 1024) != tiling.pixel_tile(n, 1024)  # the rules differ here
    np.testing.assert_array_equal(equal, powers)

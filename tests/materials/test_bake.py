"""Baking into atlas maps: a checker on a floor quad, split into two charts, lands on every texel
as its surface point says (analytic squares, continuous across the seam), grows into the gutter,
and leaves other materials' texels alone."""

import numpy as np
import pytest
from scipy.ndimage import binary_dilation

from invrender.materials import Transform, material
from invrender.materials.bake import bake_maps, evaluate_texels, texel_coordinates
from invrender.scene.atlas import rasterize_atlas
from invrender.scene.types import Atlas, Maps, Mesh

A, B = np.array([0.8, 0.6, 0.4]), np.array([0.1, 0.2, 0.3])


def floor_mesh():
    """A 2 m x 1 m floor (y = 0) as two 1 m squares, each its own chart in the atlas (left and
    right halves of UV space, with a gutter between), and a wall quad (a third chart) at x = 3."""
    positions = np.array(
        [
            [0, 0, 0],
            [1, 0, 0],
            [1, 0, 1],
            [0, 0, 1],
            [1, 0, 0],
            [2, 0, 0],
            [2, 0, 1],
            [1, 0, 1],
            [3, 0, 0],
            [3, 1, 0],
            [3, 1, 1],
            [3, 0, 1],
        ],
        np.float32,
    )
    faces = np.array([[0, 2, 1], [0, 3, 2], [4, 6, 5], [4, 7, 6], [8, 9, 10], [8, 10, 11]], np.int32)
    square = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32) * 0.4
    uvs = np.concatenate([square + [0.05, 0.05], square + [0.55, 0.05], square + [0.05, 0.55]]).astype(np.float32)
    return Mesh(positions, faces, uvs)


@pytest.fixture(scope="module")
def texels():
    return rasterize_atlas(floor_mesh(), 64, 64)


def test_floor_checker_is_analytic_and_continuous_across_charts(texels):
    checker = material("checker")
    params = {"colour_a": tuple(A), "colour_b": tuple(B)}
    coords = texel_coordinates(texels, faces=[0, 1, 2, 3])  # box mapping: the floor's (x, z)
    maps = bake_maps(Atlas.uniform((64, 64), kd=0.5, ks=0.0, ka=0.3), coords, checker, params, Transform(scale=2.0))
    p = texels.position[coords.selected].astype(np.float64)
    # scale 2: squares of 0.25 m; square (i, j) = (floor(4 x), floor(4 z)) is colour a when i + j is even
    parity = (np.floor(4 * p[:, 0]) + np.floor(4 * p[:, 2])) % 2
    # texels within blur distance of a square's edge are blends: leave them out
    edge = np.minimum(np.abs(4 * p[:, 0] - np.round(4 * p[:, 0])), np.abs(4 * p[:, 2] - np.round(4 * p[:, 2])))
    interior = edge > 0.05
    expected = np.where(parity[:, None] == 0, A, B)
    got = maps.kd[coords.selected]
    assert interior.sum() > 500
    assert np.abs(got[interior] - expected[interior]).max() < 1e-5
    assert set(np.unique(np.round(p[interior, 0] // 1))) == {0.0, 1.0}  # both charts checked
    assert np.allclose(maps.ks[coords.selected], 0.04) and np.allclose(maps.ka[coords.selected], 0.25)


def test_gutter_is_grown_and_other_materials_untouched(texels):
    before = Atlas.uniform((64, 64), kd=0.5, ks=0.0, ka=0.3)
    coords = texel_coordinates(texels, faces=[0, 1, 2, 3])
    maps = bake_maps(before, coords, material("plain"), {"colour": (0.2, 0.4, 0.6)}, dilation=2)
    wall = texels.mask & ~coords.selected
    assert wall.sum() > 100
    assert np.array_equal(maps.kd[wall], before.kd[wall]) and np.array_equal(maps.ka[wall], before.ka[wall])
    gutter = ~texels.mask & np.all(np.isclose(maps.kd, [0.2, 0.4, 0.6]), axis=-1)
    assert gutter.sum() > 50  # a ring of up to 2 texels around the floor's charts
    # nothing lands more than 2 texels from a floor chart
    near = binary_dilation(coords.selected, np.ones((3, 3), bool), iterations=2)
    assert not np.any(gutter & ~near)
    assert np.all(before.kd == 0.5)  # the input is not written


def test_maps_with_a_sky_bake_alike(texels):
    before = Maps.uniform((64, 64), kd=0.5, kg=0.7)
    coords = texel_coordinates(texels, faces=[4, 5])
    maps = bake_maps(before, coords, material("plain"), {"colour": (0.1, 0.2, 0.3)})
    assert isinstance(maps, Maps) and np.all(maps.kg == 0.7) and maps.kg is not before.kg
    assert np.allclose(maps.kd[coords.selected], [0.1, 0.2, 0.3])


def test_plane_coordinates_and_differentiable_texels(texels):
    import torch

    coords = texel_coordinates(texels, faces=[4, 5], plane=((3, 0, 0), (0, 0, 1), (0, 1, 0)), meters_per_unit=0.5)
    p = texels.position[coords.selected]
    assert np.allclose(coords.uv, np.stack([p[:, 2], p[:, 1]], axis=1) / 0.5, atol=1e-6)
    colour = torch.tensor([0.3, 0.3, 0.3], requires_grad=True)
    kd, _, _ = evaluate_texels(coords, material("plain"), {"colour": colour})
    kd.sum().backward()
    assert torch.allclose(colour.grad, torch.full((3,), float(coords.selected.sum())))

"""The sky's start and prior: below the support's horizon the support's radiance, above it white;
neighbouring sky texels pulled together in log radiance; the ground below the horizon lit by the
sky above it."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from invrender.duplicates_material.material import Ground, TexelMaterial
from invrender.duplicates_material.support import below_horizon, first_sky, irradiance_weights
from invrender.scene.cubemap import texel_directions
from invrender.scene.neighbours import sky_neighbour_pairs
from invrender.scene.types import Atlas, Mesh


def _tilted_floor(normal) -> Mesh:
    normal = np.asarray(normal, np.float64) / np.linalg.norm(normal)
    u = np.cross(normal, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)  # (u, v, normal) right-handed: the quad faces +normal
    corners = np.array([-u - v, u - v, u + v, -u + v], np.float32)
    return Mesh(positions=corners, faces=np.array([[0, 1, 2], [0, 2, 3]], np.int32), uvs=np.zeros((4, 2), np.float32))


def test_the_sky_below_the_supports_horizon_starts_at_its_radiance():
    normal = np.array([0.2, 1.0, -0.1])
    below = below_horizon(8, _tilted_floor(normal))
    np.testing.assert_array_equal(below, texel_directions(8) @ normal < 0)
    kg = first_sky(8, below, [0.3, 0.2, 0.1])
    assert 0.4 < below.mean() < 0.6
    np.testing.assert_array_equal(kg[below], np.broadcast_to([0.3, 0.2, 0.1], kg[below].shape).astype(np.float32))
    np.testing.assert_array_equal(kg[~below], 1.0)


def test_without_a_support_the_sky_starts_white():
    np.testing.assert_array_equal(first_sky(4, None, [0.3, 0.2, 0.1]), 1.0)


def test_sky_pairs_join_each_texel_to_its_neighbours_across_the_cube_edges():
    n = 6
    pairs = sky_neighbour_pairs(n)
    directions = texel_directions(n).reshape(-1, 3)
    angles = np.degrees(np.arccos(np.clip((directions[pairs[:, 0]] * directions[pairs[:, 1]]).sum(-1), -1, 1)))
    assert angles.max() < 2.2 * 90 / n  # neighbours and diagonal neighbours, never across the sphere
    faces = np.repeat(np.arange(6), n * n)
    assert (faces[pairs[:, 0]] != faces[pairs[:, 1]]).sum() >= 12 * n  # every cube edge joins two faces
    assert np.bincount(pairs.ravel(), minlength=6 * n * n).min() >= 7  # a cube corner's texel has 7
    below = below_horizon(n, _tilted_floor([0.0, 1.0, 0.3]))
    split = sky_neighbour_pairs(n, below)
    side = below.reshape(-1)
    assert len(split) < len(pairs) and (side[split[:, 0]] == side[split[:, 1]]).all()


def _material(kg) -> TexelMaterial:
    atlas = Atlas.uniform((4, 4), kd=0.5, ks=0.04, ka=0.1)
    return TexelMaterial({"object": atlas}, kg, {"object": np.zeros((0, 2), np.int64)}, sky_neighbour_pairs(4))


def test_the_sky_prior_is_zero_for_a_uniform_sky_and_pulls_an_outlier_towards_its_neighbours():
    settings = {"smoothness": 0.0, "binary": 0.0, "sparsity": 0.0, "energy": 0.0, "sky_smoothness": 1.0}
    uniform = _material(np.full((6, 4, 4, 3), 0.7, np.float32))
    assert float(uniform.regularisers(settings)["sky_smoothness"]) == 0.0
    kg = np.full((6, 4, 4, 3), 0.7, np.float32)
    kg[2, 1, 1] = 7.0
    spiky = _material(kg)
    term = spiky.regularisers(settings)["sky_smoothness"]
    assert float(term) > 0
    term.backward()
    grad = spiky.sky.grad.numpy()
    assert (grad[2, 1, 1] > 0).all()  # a descent step lowers the outlier
    assert (grad.reshape(-1, 3)[np.abs(grad.reshape(-1, 3)).sum(-1) > 0] != 0).any()
    assert torch.isfinite(spiky.sky.grad).all()


def _ground(n: int, normal, albedo: float = 0.18) -> Ground:
    floor = _tilted_floor(normal)
    return Ground(below_horizon(n, floor), irradiance_weights(n, floor), albedo)


@pytest.mark.parametrize("n", [8, 16])
def test_the_irradiance_weights_integrate_the_cosine_over_the_sky(n):
    """Analytic: a uniform sky L pours E = pi L onto a plane, a sky L = cos(theta) E = 2 pi / 3
    (the cosine at texel centres, exact solid angles: within 1 % at 8 texels a side)."""
    normal = np.array([0.3, 1.0, 0.2])
    floor = _tilted_floor(normal)
    w = irradiance_weights(n, floor)
    cos = texel_directions(n) @ (normal / np.linalg.norm(normal))
    assert (w[below_horizon(n, floor)] == 0).all()
    assert abs(w.sum() / np.pi - 1) < 0.01
    assert abs((w * np.clip(cos, 0, None)).sum() / (2 * np.pi / 3) - 1) < 0.01


def test_the_ground_reflects_the_sky_above_it_as_a_grey_lambertian_plane():
    """Under a uniform sky L a ground of albedo a has radiance a L (a E / pi); above the horizon
    the sky is its own; below it, whatever the texels held."""
    n, sky = 8, np.array([0.5, 1.0, 2.0], np.float32)
    ground = _ground(n, [0.0, 1.0, 0.0], albedo=0.25)
    kg = np.broadcast_to(sky, (6, n, n, 3)).copy()
    kg[ground.below] = 7.0  # ignored
    out = ground.radiance(torch.from_numpy(kg)).numpy()
    np.testing.assert_allclose(out[ground.below], np.broadcast_to(0.25 * sky, out[ground.below].shape), rtol=0.01)
    np.testing.assert_array_equal(out[~ground.below], kg[~ground.below])


def test_the_grounds_gradient_reaches_the_sky_above_through_the_irradiance():
    """d(sum of the ground's texels)/d(g_i) = count x albedo / pi x w_i x kg_i for a sky texel
    above the horizon (kg = exp(g)); the ground's own values get none."""
    n = 4
    ground = _ground(n, [0.1, 1.0, -0.2], albedo=0.18)
    rng = np.random.default_rng(0)
    kg = rng.uniform(0.2, 3.0, (6, n, n, 3)).astype(np.float32)
    atlas = Atlas.uniform((4, 4), kd=0.5, ks=0.04, ka=0.1)
    no_pairs = {"object": np.zeros((0, 2), np.int64)}
    material = TexelMaterial({"object": atlas}, kg, no_pairs, sky_neighbour_pairs(n), ground)
    material.kg()[torch.from_numpy(ground.below)].sum().backward()
    grad = material.sky.grad.numpy()
    expected = ground.below.sum() * 0.18 / np.pi * ground.weights[..., None] * kg
    np.testing.assert_allclose(grad, expected, rtol=1e-4, atol=1e-7)
    assert (grad[ground.below] == 0).all()

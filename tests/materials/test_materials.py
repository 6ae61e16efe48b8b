"""Each material: its maps at known points (analytic), its parameters' gradients (central finite
differences), the transform's convention, and its bounds."""

import numpy as np
import pytest
import torch

from invrender.materials import MATERIALS, PRESETS, Transform, material
from invrender.materials.base import KA_MIN, mean_albedo


def points(n=512, seed=0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand((n, 2), generator=g) * 3.0


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_maps_shapes_ranges_and_common_parameters(name):
    m = material(name)
    kd, ks, ka = m.evaluate(points(), {"roughness": 0.3, "specular": 0.05})
    assert kd.shape == (512, 3) and ks.shape == (512,) and ka.shape == (512,)
    assert float(kd.min()) >= 0.0 and float(kd.max()) <= 1.0
    assert torch.allclose(ks, torch.tensor(0.05)) and torch.allclose(ka, torch.tensor(0.09))
    # ka is alpha^2, clamped where the renderer clamps it (render/bsdf.py)
    assert float(m.evaluate(points(4), {"roughness": 0.0})[2][0]) == pytest.approx(KA_MIN)


@pytest.mark.parametrize("name", sorted(MATERIALS))
def test_every_texture_parameter_gradient_matches_finite_differences(name):
    """d sum(w * kd) / d theta by autograd against central differences (float64: step 1e-5 of
    the range, tolerance 1 % of the largest derivative), at values inside the ranges and 512 points."""
    m = material(name)
    uv = points().double()
    w = torch.rand((512, 3), generator=torch.Generator().manual_seed(1), dtype=torch.float64)
    # values drawn inside 20-80 % of each range (two colours drawn alike would hide each other)
    rng = np.random.default_rng(2)
    mid = {
        p.name: p.tensor(p.low + (p.high - p.low) * rng.uniform(0.2, 0.8, 3 if p.is_colour else None)).double()
        for p in m.params
    }
    transform = Transform(1.3, 20.0, (0.2, 0.7))

    def objective(params):
        return (m.evaluate(uv, params, transform, footprint=0.02)[0] * w).sum()

    for p in m.params:
        if not p.texture:
            continue
        params = {k: v.clone().requires_grad_(k == p.name) for k, v in mid.items()}
        (grad,) = torch.autograd.grad(objective(params), params[p.name])
        h = 1e-5 * (p.high - p.low)
        fd = torch.zeros_like(grad)
        for i in range(grad.numel()):
            plus = {k: v.detach().clone() for k, v in params.items()}
            minus = {k: v.detach().clone() for k, v in params.items()}
            plus[p.name].view(-1)[i] += h
            minus[p.name].view(-1)[i] -= h
            fd.view(-1)[i] = (objective(plus) - objective(minus)) / (2 * h)
        scale = float(fd.abs().max())
        assert scale > 1e-3, f"{name}.{p.name} does not change kd"
        assert float((grad - fd).abs().max()) <= 0.01 * scale, (name, p.name, grad, fd)


def test_transform_maps_uv_to_material_space():
    # p = s R(-theta) uv + offset: the pattern turns by +theta (counter-clockwise).
    t = Transform(scale=2.0, rotation_deg=90.0, offset=(0.5, 0.0))
    p = t.apply(torch.tensor([[1.0, 0.0], [0.0, 1.0]]))
    assert torch.allclose(p, torch.tensor([[0.5, -2.0], [2.5, 0.0]]), atol=1e-6)
    # A checker turned by 90 degrees is the same checker shifted by one square.
    checker = material("checker")
    uv = points(256)
    a = checker.evaluate(uv, None, Transform(2.0, 90.0))[0]
    b = checker.evaluate(uv, None, Transform(2.0, 0.0, (0.5, 0.0)))[0]
    assert torch.allclose(a, b, atol=1e-4)


def test_checker_squares_and_tile_grout_at_known_points():
    checker = material("checker")
    kd = checker.evaluate(torch.tensor([[0.25, 0.25], [0.75, 0.25], [0.75, 0.75]]))[0]
    a, b = checker.defaults()["colour_a"], checker.defaults()["colour_b"]
    assert torch.allclose(kd, torch.stack([a, b, a]))
    tiles = material("tiles")
    params = {"variation": 0.0, "grout_width": 0.1, "aspect": 2.0, "bond": 0.5}
    # row 0 spans x in [0, 2); row 1 is shifted by half a tile: its joint is at x = 1
    kd = tiles.evaluate(torch.tensor([[1.0, 0.5], [1.0, 1.5], [0.5, 1.02], [1.5, 1.5]]), params)[0]
    tile, grout = tiles.defaults()["tile_colour"], tiles.defaults()["grout_colour"]
    assert torch.allclose(kd, torch.stack([tile, grout, grout, tile]), atol=1e-6)


def test_noise_and_wood_are_deterministic_and_not_flat():
    for name in ("noise", "wood", "fabric"):
        m = material(name)
        a = m.image(32, None, Transform(2.0)).numpy()
        b = m.image(32, None, Transform(2.0)).numpy()
        assert np.array_equal(a, b)
        assert a.std() > 0.02, name


def test_mean_albedo_of_a_checker_is_the_mean_of_its_colours():
    checker = material("checker")
    params = {"colour_a": (0.8, 0.4, 0.2), "colour_b": (0.2, 0.0, 0.6)}
    assert np.allclose(mean_albedo(checker, params).numpy(), [0.5, 0.2, 0.4], atol=2e-3)


def test_presets_respect_bounds_and_energy():
    for preset in PRESETS:
        params = preset.params()
        for p in preset.type.params:
            assert float(params[p.name].min()) >= p.low and float(params[p.name].max()) <= p.high, preset.name
        kd, ks, _ = preset.type.evaluate(points(64), params)
        assert float((kd + ks[:, None]).max()) <= 1.0 + 1e-6, preset.name
    # the bound holds beyond the presets: tiles brightened by the largest variation
    tiles = material("tiles")
    kd, ks, _ = tiles.evaluate(points(256), {"tile_colour": (0.9, 0.9, 0.9), "variation": 0.5, "specular": 0.08})
    assert float((kd + ks[:, None]).max()) <= 1.0 + 1e-6 and float(kd.max()) == pytest.approx(0.92)


def test_unknown_parameter_is_named():
    with pytest.raises(KeyError, match="grout"):
        material("checker").defaults(grout_width=0.1)

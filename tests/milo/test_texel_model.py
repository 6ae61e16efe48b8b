"""The `texels` model against its definition: where it starts (the emitters and the per-texel
guess of the photographs), the energy bound it keeps whatever its parameters, and its preset."""

import numpy as np
import pytest
import torch

from invrender.milo.config import resolve
from invrender.milo.texel_model import F0, TexelMaps, reflectance_start
from invrender.milo.texels import Texels
from invrender.render.adjoint import GRAD_CHANNELS
from invrender.scene.atlas import AtlasTexels
from invrender.scene.types import SceneError


def _strip(n: int = 12) -> AtlasTexels:
    """A 4 x n atlas whose middle two rows are covered: texels 0.1 m apart along x."""
    mask = np.zeros((4, n), bool)
    mask[1:3] = True
    x, y = np.meshgrid(np.arange(n) * 0.1, np.arange(4) * 0.1)
    position = np.stack([x, y, np.zeros_like(x)], -1).astype(np.float32)
    normal = np.broadcast_to(np.float32([0, 0, 1]), position.shape).copy()
    triangle = np.where(mask, 0, -1).astype(np.int32)
    return AtlasTexels(triangle, np.zeros((4, n, 3), np.float32), position, normal, mask)


def test_the_per_texel_guess_puts_the_median_reflector_at_one_half():
    radiance = np.array([[0.2, 0.2, 0.2], [0.4, 0.4, 0.4], [0.8, 0.4, 0.2], [30.0, 30.0, 30.0], [1.0, 1.0, 1.0]])
    seen = np.array([True, True, True, True, False])
    emitting = np.array([False, False, False, True, False])
    kd = reflectance_start(radiance, seen, emitting)
    # reflectors' median luminance (mean RGB) is 0.4 -> factor 1.25; the lamp and the unseen texel
    # are not reflectors the photographs show: 0.5
    np.testing.assert_allclose(kd[:3], [[0.25] * 3, [0.5] * 3, [0.95, 0.5, 0.25]], rtol=1e-6)
    np.testing.assert_allclose(kd[3:], 0.5)


def test_warm_start_makes_the_bright_texels_emit_and_the_others_reflect_their_guess():
    atlas = _strip()
    texels = Texels.from_atlas(atlas)
    settings = resolve("texels")
    model = TexelMaps(settings, texels, sky=0.5)
    radiance = np.zeros((4, 12, 3), np.float32)
    radiance[1:3] = 0.3
    radiance[1:3, :2] = 20.0  # a lamp at one end
    radiance[1:3, 6] = [0.6, 0.3, 0.15]
    seen = np.where(atlas.mask, 2, 0)
    emitting = radiance.mean(-1) > 5.0
    model.warm_start(texels, emitting, radiance, seen, settings)
    maps = model.texel_surface(texels, None)["maps"].detach().numpy()
    at = {(r, c): i for i, (r, c) in enumerate(zip(texels.rows, texels.cols))}
    lamp, wall, tinted = at[(1, 0)], at[(1, 4)], at[(2, 6)]
    np.testing.assert_allclose(maps[lamp, GRAD_CHANNELS["ke"]], 20.0, rtol=1e-5)
    np.testing.assert_allclose(maps[lamp, GRAD_CHANNELS["kd"]], 0.0)
    np.testing.assert_allclose(maps[wall, GRAD_CHANNELS["ke"]], 0.0)
    # the reflectors' median 0.3 is put at 0.5; ks starts at a dielectric's
    np.testing.assert_allclose(maps[wall, GRAD_CHANNELS["kd"]], 0.5, rtol=1e-3)
    np.testing.assert_allclose(maps[tinted, GRAD_CHANNELS["kd"]], [0.95, 0.5, 0.25], rtol=1e-3)  # clipped
    np.testing.assert_allclose(maps[wall, GRAD_CHANNELS["ks"]], F0, rtol=1e-3)
    # a padding texel (row 0, beside the lamp's column 0) takes its covered neighbour's kind
    assert maps[at[(0, 0)], GRAD_CHANNELS["ke"]].min() > 1.0


def test_no_texel_reflects_more_than_it_receives_whatever_the_parameters():
    texels = Texels.from_atlas(_strip())
    model = TexelMaps(resolve("texels"), texels, sky=0.5)
    with torch.no_grad():
        for parameter in (model.kd_logit, model.ks_logit):
            parameter.copy_(torch.randn_like(parameter) * 8.0)
    maps = model.texel_surface(texels, None)["maps"].detach()
    total = maps[:, GRAD_CHANNELS["kd"]] + maps[:, GRAD_CHANNELS["ks"]]
    assert float(total.max()) <= 1.0 + 1e-6
    assert float(total.max()) > 0.9  # the bound is reached, not avoided by staying dark


def test_the_texels_preset_and_its_refusals():
    settings = resolve("texels")
    assert settings["model"] == "texels" and settings["iterations"] == 40 and settings["rays"] == 8192
    assert settings["reflectance_passes"] == 4 and settings["max_bounces"] == 10
    with pytest.raises(SceneError, match="model: expected one of network, texels"):
        resolve("demo", {"model": "voxels"})

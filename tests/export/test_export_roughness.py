"""The roughness mapping and its measured error (roughness.py, quoted in docs/export.md)."""

import numpy as np
import pytest

from invrender.export.roughness import (
    KA_MIN,
    _half_vector_grid,
    beckmann_d,
    ggx_d,
    ka_from_roughness,
    mapping_error,
    roughness_from_ka,
)


def test_mapping_keeps_alpha_and_inverts_within_float32():
    ka = np.geomspace(KA_MIN, 1.0, 1000).astype(np.float32)
    r = roughness_from_ka(ka)
    assert np.allclose(r.astype(np.float64) ** 2, np.sqrt(ka), rtol=1e-6)  # GGX alpha = r^2 = Beckmann alpha
    assert np.allclose(ka_from_roughness(r), ka, rtol=1e-6)
    assert ka_from_roughness(0.0) == np.float32(KA_MIN) and ka_from_roughness(2.0) == 1.0


@pytest.mark.parametrize("alpha", [0.03, 0.2, 1.0])
def test_the_quadrature_integrates_both_distributions_to_one(alpha):
    """Any microfacet D has unit projected area, integral D cos(theta_h) = 1: an independent check
    of the grid the mapping error is measured on."""
    h, weight = _half_vector_grid(alpha, 1024, 64)
    assert (beckmann_d(h[:, 2], alpha) * h[:, 2]) @ weight == pytest.approx(1.0, abs=1e-5)
    assert (ggx_d(h[:, 2], alpha) * h[:, 2]) @ weight == pytest.approx(1.0, abs=1e-5)


@pytest.mark.parametrize(
    "ka, angle, albedo_ours, albedo_usd, l1",
    [
        (0.02, 0, 1.000, 0.975, 0.38),  # the glossy table of the demo room
        (0.3, 0, 0.849, 0.641, 0.26),  # its walls and floor
        (0.3, 60, 0.881, 0.656, 0.53),
    ],
)
def test_the_mapping_error_is_what_the_docs_say(ka, angle, albedo_ours, albedo_usd, l1):
    error = mapping_error(ka, np.radians(angle))
    assert error["albedo_ours"] == pytest.approx(albedo_ours, abs=2e-3)
    assert error["albedo_usd"] == pytest.approx(albedo_usd, abs=2e-3)
    assert error["lobe_l1"] == pytest.approx(l1, abs=0.01)

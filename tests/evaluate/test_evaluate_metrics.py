"""The image metrics against their definitions: PSNR by the formula, SSIM of flat images by Wang
et al.'s closed form, NCC's invariance to scale and offset, and the tone mapping's exposure."""

import numpy as np
import pytest

from invrender.evaluate.metrics import PSNR_CAP_DB, image_metrics, mse, ncc, psnr, reference_exposure, ssim, tone_map
from invrender.scene.images import linear_to_srgb


@pytest.fixture
def image():
    return np.random.default_rng(0).random((40, 48, 3))


def test_psnr_of_identical_images_is_the_cap(image):
    assert psnr(image, image.copy()) == PSNR_CAP_DB


def test_psnr_of_a_known_noise_level_matches_the_formula(image):
    # +-0.05 in a checkerboard: every squared difference is 0.0025, so PSNR = 10 log10(1 / 0.0025)
    sign = np.where(np.indices(image.shape).sum(axis=0) % 2, 1.0, -1.0)
    noisy = image + 0.05 * sign
    assert mse(noisy, image) == pytest.approx(0.0025, rel=1e-12)
    assert psnr(noisy, image) == pytest.approx(26.020599913279625, abs=1e-9)
    assert psnr(noisy, image, peak=2.0) == pytest.approx(26.020599913279625 + 20 * np.log10(2), abs=1e-9)


def test_ssim_of_identical_images_is_one_and_of_flat_images_the_closed_form(image):
    assert ssim(image, image.copy()) == pytest.approx(1.0, abs=1e-6)
    # Flat images: no variance, so SSIM = (2 mu_a mu_b + C1) / (mu_a^2 + mu_b^2 + C1), C1 = (0.01 L)^2
    a, b = np.full((32, 32, 3), 0.2), np.full((32, 32, 3), 0.6)
    mu_a, mu_b, c1 = 0.2 * 255, 0.6 * 255, (0.01 * 255) ** 2
    assert ssim(a, b) == pytest.approx((2 * mu_a * mu_b + c1) / (mu_a**2 + mu_b**2 + c1), rel=1e-5)
    noise = np.random.default_rng(1).normal(0, 1, image.shape)
    scores = [ssim(image, np.clip(image + sigma * noise, 0, 1)) for sigma in (0.02, 0.1, 0.3)]
    assert 1 > scores[0] > scores[1] > scores[2] and scores[2] < 0.8, scores


def test_ncc_is_one_for_scaled_and_offset_copies_and_minus_one_for_negated(image):
    assert ncc(image, 2 * image) == pytest.approx(1.0, abs=1e-12)
    assert ncc(image, 2 * image + 0.3) == pytest.approx(1.0, abs=1e-12)
    assert ncc(image, -image) == pytest.approx(-1.0, abs=1e-12)
    other = np.random.default_rng(5).random(image.shape)
    assert abs(ncc(image, other)) < 0.05  # independent noise
    assert ncc(image, np.zeros_like(image)) == 0.0


def test_weighted_mse_is_the_weighted_mean_over_texels_and_channels():
    a, b = np.zeros((2, 3)), np.array([[1.0, 1.0, 1.0], [2.0, 2.0, 2.0]])
    assert mse(a, b, weights=np.array([3.0, 1.0])) == pytest.approx((3 * 1 + 1 * 4) / 4)


def test_tone_mapping_puts_the_reference_99th_percentile_at_one():
    radiance = np.random.default_rng(2).random((50, 50, 3)) * 7.0
    exposure = reference_exposure(radiance)
    assert np.percentile(radiance.max(axis=-1), 99) * exposure == pytest.approx(1.0)
    mapped = tone_map(radiance, exposure)
    assert mapped.min() >= 0 and mapped.max() == pytest.approx(1.0)
    assert np.allclose(mapped, linear_to_srgb(np.clip(radiance * exposure, 0, 1)))


def test_image_metrics_use_the_reference_exposure_for_both():
    reference = np.random.default_rng(3).random((30, 30, 3)) * 4.0
    metrics = image_metrics(2.0 * reference, reference)  # twice as bright: clipped more, but correlated
    assert metrics["exposure"] == pytest.approx(reference_exposure(reference))
    assert metrics["psnr_db"] < 20 and metrics["ncc"] > 0.5
    same = image_metrics(reference, reference)
    assert same["psnr_db"] == PSNR_CAP_DB and same["ssim"] == pytest.approx(1.0, abs=1e-6) and same["mse"] == 0.0

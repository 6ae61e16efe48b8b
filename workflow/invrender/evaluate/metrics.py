"""Image metrics of MILO's Table 3 (PSNR, SSIM, NCC, MSE) and the one tone mapping they are taken on.

Images are compared as a person sees them, so that a bright lamp does not decide the score:
both images go through ``tone_map`` with one exposure, fixed from the reference image (its 99th
percentile of the largest channel maps to 1, as ``scene.images.write_png_preview`` does for the
previews), clipped to [0, 1] and sRGB-encoded. Every metric below then works on values in [0, 1].
"""

from __future__ import annotations

import cv2
import numpy as np

from ..scene.images import linear_to_srgb

__all__ = ["PSNR_CAP_DB", "reference_exposure", "tone_map", "mse", "psnr", "ssim", "ncc", "image_metrics"]

# PSNR of identical images is infinite, which JSON cannot hold: it is reported as this cap
# (the PSNR of an MSE of 1e-10 on a [0, 1] scale, far above any Monte Carlo render's).
PSNR_CAP_DB = 100.0
EXPOSURE_PERCENTILE = 99.0


def reference_exposure(linear_rgb) -> float:
    """The exposure that maps the 99th percentile of the image's largest channel to 1 (1 if it is 0)."""
    level = float(np.percentile(np.asarray(linear_rgb, np.float64).max(axis=-1), EXPOSURE_PERCENTILE))
    return 1.0 / level if level > 0 else 1.0


def tone_map(linear_rgb, exposure: float) -> np.ndarray:
    """Linear radiance -> display values in [0, 1]: times exposure, clipped, sRGB-encoded."""
    return linear_to_srgb(np.asarray(linear_rgb, np.float64) * exposure)


def mse(a, b, weights=None) -> float:
    """Mean of the squared differences over every element (channels included); ``weights``
    (broadcasting over the leading dimensions) make it a weighted mean."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    squared = (a - b) ** 2
    if weights is None:
        return float(squared.mean())
    w = np.broadcast_to(
        np.asarray(weights, np.float64).reshape(np.shape(weights) + (1,) * (a.ndim - np.ndim(weights))), a.shape
    )
    return float((squared * w).sum() / w.sum())


def psnr(a, b, peak: float = 1.0) -> float:
    """10 log10(peak^2 / MSE) in dB, capped at PSNR_CAP_DB (identical images)."""
    error = mse(a, b)
    return PSNR_CAP_DB if error <= peak**2 * 10 ** (-PSNR_CAP_DB / 10) else float(10.0 * np.log10(peak**2 / error))


def ssim(a, b) -> float:
    """Mean SSIM (Wang et al. 2004: 11 x 11 Gaussian window, sigma 1.5, K1 0.01, K2 0.03) over
    pixels and channels, for images in [0, 1]: OpenCV's quality module, whose constants are those
    of an 8-bit range, so the images are scaled to [0, 255] (as floats: no rounding)."""
    a = np.ascontiguousarray(np.asarray(a, np.float32) * 255.0)
    b = np.ascontiguousarray(np.asarray(b, np.float32) * 255.0)
    channels = 1 if a.ndim == 2 else a.shape[2]
    return float(np.mean(cv2.quality.QualitySSIM_compute(a, b)[0][:channels]))


def ncc(a, b) -> float:
    """Normalised cross-correlation (zero-mean, over every pixel and channel): 1 for images that
    differ by a positive scale and offset; 0 if either is constant."""
    a = np.asarray(a, np.float64).ravel()
    b = np.asarray(b, np.float64).ravel()
    a, b = a - a.mean(), b - b.mean()
    norm = np.sqrt((a * a).sum() * (b * b).sum())
    return float((a * b).sum() / norm) if norm > 0 else 0.0


def image_metrics(test_linear, reference_linear, exposure: float | None = None) -> dict:
    """PSNR, SSIM, NCC and MSE of two linear renders on the tone mapping of ``reference_linear``."""
    exposure = reference_exposure(reference_linear) if exposure is None else exposure
    test, reference = tone_map(test_linear, exposure), tone_map(reference_linear, exposure)
    return {
        "psnr_db": psnr(test, reference),
        "ssim": ssim(test, reference),
        "ncc": ncc(test, reference),
        "mse": mse(test, reference),
        "exposure": float(exposure),
    }

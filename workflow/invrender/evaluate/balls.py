"""Shading balls: MILO's material error (section 4.1, "we render a shading ball for each pixel").

A texel's material (kd, ks, ka) is shown as a small sphere, so that errors are weighed by what
they do to the appearance instead of by raw parameter distance (ka = 0.01 against 0.02 is a large
visible difference; kd's blue channel 0.9 against 0.8 under a red light is none):

- the sphere: orthographic, BALL_SIZE x BALL_SIZE pixels, seen along -z (the viewer at +z,
  wo = (0, 0, 1)); pixel (i, j) looks at x = 2 (j + 0.5) / N - 1, y = 1 - 2 (i + 0.5) / N and
  shows the sphere where x^2 + y^2 < 1, with normal (x, y, sqrt(1 - x^2 - y^2)); the other
  pixels are left out of the mean;
- the light: the three directional lights of BALL_LIGHTS (unit direction towards the light,
  irradiance on a surface facing it): a key light from the upper left, a fill from the right and a
  weak light from the viewer, which puts a specular highlight in the middle of the ball. No
  shadows (a sphere lit by directional lights shadows only where n.wi <= 0, which the BRDF's
  cosine already zeroes);
- the shading: radiance = sum over lights of E_k f(wi_k, wo) (n . wi_k), MILO's BRDF evaluated by
  the float64 reference ``render.bsdf.milo_bsdf_cos`` (the same numbers the kernels are tested
  against), then clipped to [0, 1] as the ball would be displayed: a smooth surface's highlight
  saturates, as in the paper's figures, instead of one texel's peak outweighing all others.

``ball_mse`` is the mean over texels of each texel's mean squared difference over the ball's
pixels and the three channels.
"""

from __future__ import annotations

import numpy as np

from ..render.bsdf import milo_bsdf_cos, normalize

__all__ = ["BALL_SIZE", "BALL_LIGHTS", "ball_normals", "shade_balls", "ball_mse"]

BALL_SIZE = 16
# (direction towards the light, irradiance): a white diffuse ball (kd = 1) peaks near radiance 1.
BALL_LIGHTS = (
    ((-1.0, 1.0, 1.0), 2.0),  # key: upper left, in front
    ((1.0, 0.2, 0.6), 0.8),  # fill: right
    ((0.0, 0.0, 1.0), 0.5),  # from the viewer: the highlight in the middle
)
CHUNK = 2048  # texels per batch: (2048, 16^2, 3) float64 temporaries of 12 MB


def ball_normals(size: int = BALL_SIZE) -> np.ndarray:
    """(P, 3) normals of the ball's pixels inside the sphere's outline, row by row."""
    centres = (np.arange(size) + 0.5) * 2.0 / size - 1.0
    y, x = -centres[:, None], centres[None, :]
    x, y = np.broadcast_arrays(x, y)
    r2 = x * x + y * y
    inside = r2 < 1.0
    return np.stack([x[inside], y[inside], np.sqrt(1.0 - r2[inside])], axis=-1)


def shade_balls(kd, ks, ka, size: int = BALL_SIZE) -> np.ndarray:
    """(T, P, 3) displayed radiance of T materials' balls: kd, ks (T, 3), ka (T,)."""
    normals = ball_normals(size)[None]  # (1, P, 3)
    wo = np.array([0.0, 0.0, 1.0])
    kd, ks = np.asarray(kd, np.float64)[:, None], np.asarray(ks, np.float64)[:, None]
    ka = np.asarray(ka, np.float64)[:, None]
    radiance = 0.0
    for direction, irradiance in BALL_LIGHTS:
        wi = normalize(np.asarray(direction, np.float64))
        radiance = radiance + irradiance * milo_bsdf_cos(normals, wo, wi, kd, ks, ka)
    return np.clip(radiance, 0.0, 1.0)


def ball_errors(recovered: tuple, truth: tuple, size: int = BALL_SIZE) -> np.ndarray:
    """Per texel, the mean squared difference of the two balls: recovered and truth are
    (kd (T, 3), ks (T, 3), ka (T,)) each."""
    count = len(recovered[0])
    errors = np.empty(count)
    for start in range(0, count, CHUNK):
        sl = slice(start, start + CHUNK)
        a = shade_balls(*(m[sl] for m in recovered), size=size)
        b = shade_balls(*(m[sl] for m in truth), size=size)
        errors[sl] = ((a - b) ** 2).mean(axis=(1, 2))
    return errors


def ball_mse(recovered: tuple, truth: tuple, size: int = BALL_SIZE) -> float:
    """The material MSE: shading balls' squared difference, averaged over pixels, channels, texels."""
    return float(ball_errors(recovered, truth, size).mean())

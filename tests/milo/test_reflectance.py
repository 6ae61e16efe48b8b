"""The texels model's light-transport passes (milo/reflectance.py): the smoothing and the damped,
level-keeping step against hand-computed values, and the passes on a capture against its truth."""

import numpy as np
import pytest
from milo_capture import TINY, training_on

from invrender.bench.milo_independent import truth_maps
from invrender.milo.config import resolve
from invrender.milo.importance import TexelPixels, emitting_start, per_group_median
from invrender.milo.reflectance import correction, refine_reflectance, smoothed_log
from invrender.milo.stage import capture_scale
from invrender.scene.atlas import AtlasTexels
from invrender.scene.capture import read_view
from invrender.scene.types import SceneError


def test_smoothing_averages_log_ratios_over_neighbours_and_fills_unseen_texels():
    ratio = np.ones((1, 4, 3))
    ratio[0, 0], ratio[0, 1] = 4.0, 1.0  # geometric mean 2
    weight = np.array([[True, True, False, False]])
    pairs = np.array([[0, 1], [1, 2]])  # texel 3 has no neighbour
    mean, reached = smoothed_log(ratio, weight, pairs)
    np.testing.assert_allclose(np.exp(mean[0, :2]), 2.0)
    np.testing.assert_allclose(np.exp(mean[0, 2]), 1.0)  # unseen: its one seen neighbour's ratio
    assert reached.tolist() == [[True, True, True, False]]


def test_the_projection_takes_each_texels_median_over_its_views():
    """per_group_median against numpy's median per group; an empty group reads 0, and one
    outlying view (a pixel on a lamp's rim) does not move a texel seen by three."""
    rng = np.random.default_rng(0)
    groups, values = rng.integers(0, 50, 400), rng.normal(size=(400, 3))
    count = np.bincount(groups, minlength=52)
    got = per_group_median(groups, values, count)
    for g in range(52):
        want = np.median(values[groups == g], axis=0) if count[g] else np.zeros(3)
        np.testing.assert_allclose(got[g], want)
    outlier = per_group_median(np.zeros(3, int), np.array([[0.5] * 3, [0.5] * 3, [40.0] * 3]), np.array([3]))
    np.testing.assert_allclose(outlier, 0.5)


def test_a_pass_keeps_the_reflectors_median_and_moves_by_the_square_root_of_the_ratio():
    captured = np.array([[[1.0] * 3, [2.0] * 3, [4.0] * 3, [9.0] * 3]])
    rendered = np.ones_like(captured)
    reflecting = np.array([[True, True, True, False]])  # the last one emits
    factor = correction(captured, rendered, reflecting, np.zeros((0, 2), np.int64), floor=0.0)
    # ratios 1, 2, 4 around their median 2, damped: 2^-1/2, 1, 2^1/2; the emitter is left alone
    np.testing.assert_allclose(factor[0, :, 0], [2**-0.5, 1.0, 2**0.5, 1.0], rtol=1e-6)
    uniform = correction(captured * 3.0, captured, reflecting, np.zeros((0, 2), np.int64), floor=0.0)
    np.testing.assert_allclose(uniform, 1.0)  # light the room lacks everywhere is not painted in


def _relative_kd_error(kd: np.ndarray, truth: np.ndarray) -> float:
    """Mean squared log error of kd after the one global factor that fits it best: the passes
    set relative reflectances, the guess's global level stays."""
    log_ratio = np.log(np.maximum(kd, 1e-3) / np.maximum(truth, 1e-3))
    return float(((log_ratio - np.median(log_ratio)) ** 2).mean())


def test_the_passes_bring_kd_closer_to_the_truth_than_the_per_texel_guess(tiny_capture):
    """The tiny room (our renderer, 16 spp) lit by two ceiling lamps and a window: the guess
    reads its lighting into kd; the passes take most of it out again."""
    settings = resolve("texels", {k: v for k, v in TINY.items() if k in ("iterations", "rays", "spp")})
    training = training_on(tiny_capture, settings)
    atlas = AtlasTexels.load(tiny_capture / "geometry" / "atlas.npz")
    pixels = TexelPixels.build(atlas, training.renderer, training.views.cameras)
    images = [read_view(tiny_capture / "cameras" / "images", c) for c in training.views.cameras]
    captured, seen = pixels.project(images)
    emitting = emitting_start(captured, seen, capture_scale(training.views)[0], settings["warm_start_fraction"])
    truth = truth_maps(tiny_capture)
    judged = (seen > 0) & ~emitting & (truth.kw < 0.5) & (truth.ke.max(-1) < 1e-3)
    before = _relative_kd_error(training.predict().kd[judged], truth.kd[judged])
    moved = refine_reflectance(training, pixels, captured, emitting)
    after = _relative_kd_error(training.predict().kd[judged], truth.kd[judged])
    assert len(moved) == settings["reflectance_passes"] and moved[-1] < moved[0]  # it converges
    assert after < 0.75 * before, (before, after)  # measured: 0.343 -> 0.221 (3 views of 32 x 24)


def test_the_passes_settings_are_checked():
    with pytest.raises(SceneError, match="reflectance_spp: expected a number >= 1"):
        resolve("texels", {"reflectance_spp": 0})

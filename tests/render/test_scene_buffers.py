"""Packing a scene for the kernels: the sampling distributions cover what the kernels index."""

import numpy as np

from invrender.render.scene_buffers import environment_distribution


def test_black_sky_distribution_covers_all_six_faces():
    """The kernel indexes env_pmf over 6 N N texels whatever the sky: a black sky once gave one
    face's worth, and the out-of-bounds reads darkened all-features renders by up to 30%."""
    for kg in (np.zeros((6, 8, 8, 3), np.float32), np.ones((6, 8, 8, 3), np.float32)):
        pmf, cdf, black = environment_distribution(kg)
        assert pmf.shape == cdf.shape == (6 * 8 * 8,)
        assert np.isclose(pmf.sum(), 1.0) and cdf[-1] == 1.0 and np.all(np.diff(cdf) >= 0)
        assert black == (kg.max() == 0)

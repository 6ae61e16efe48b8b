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


def test_emitted_power_skips_only_triangles_that_cannot_emit():
    """The UV-box shortcut gives the same powers as looking up every triangle."""
    from invrender.render.scene_buffers import LUMINANCE, _barycentric_grid, atlas_lookup, emitted_power
    from invrender.synthesize.room import make_room

    scene, _ = make_room({})
    mesh, maps = scene.mesh, scene.maps
    v = mesh.positions[mesh.faces].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), axis=1)
    uv = np.einsum("pk,fkc->fpc", _barycentric_grid(), mesh.uvs[mesh.faces].astype(np.float64))
    every = area * (atlas_lookup(maps.ke, uv) @ LUMINANCE).mean(axis=1)
    fast = emitted_power(mesh, maps)
    assert np.count_nonzero(every) > 0
    assert np.allclose(fast, every, rtol=1e-12, atol=0)

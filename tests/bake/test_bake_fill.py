"""bake fills the texels MILO-Net does not predict: the charts grow into their borders, the rest
takes the covered mean, so the scene directory holds valid maps (ka > 0)."""

import numpy as np

from invrender.bake.stage import SEAM_TEXELS, fill_uncovered
from invrender.scene.types import Maps


def test_uncovered_texels_take_their_chart_border_or_the_covered_mean():
    mask = np.zeros((16, 16), bool)
    mask[2:6, 2:6] = True  # a chart in the corner; the far corner is beyond SEAM_TEXELS of it
    maps = Maps.uniform(size=(16, 16), kd=0.0, ka=0.0)  # what milo's scatter leaves outside
    maps.kd[mask] = [0.2, 0.4, 0.6]
    maps.ka[mask] = np.linspace(0.1, 0.5, 16, dtype=np.float32)
    filled = fill_uncovered(maps, mask)

    np.testing.assert_array_equal(filled.ka[mask], maps.ka[mask])  # covered texels unchanged
    np.testing.assert_allclose(filled.kd[6, 6], [0.2, 0.4, 0.6], rtol=1e-6)  # the chart's diagonal neighbour
    assert np.isclose(filled.ka[6, 4], maps.ka[5, 3:6].mean())  # the mean of its covered 8-neighbours
    far = (15, 15)  # more than SEAM_TEXELS from the chart
    assert 15 - 5 > SEAM_TEXELS
    assert np.isclose(filled.ka[far], maps.ka[mask].mean())
    assert (filled.ka > 0).all()

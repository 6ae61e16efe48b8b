"""crops.py: a crop samples the photograph exactly where `to_full` says, at any scale."""

import numpy as np
import pytest

from invrender.duplicates.crops import instance_boxes, make_crop, make_crops


def ramp(height, width, a=0.01, b=0.003):
    """Linear in COLMAP pixel-centre coordinates: bilinear sampling and a Gaussian blur (away from
    the border) reproduce it exactly, so the crop's pixel at a point equals the ramp there."""
    y, x = np.mgrid[0:height, 0:width] + 0.5
    value = a * x + b * y
    return np.repeat(value[..., None], 3, axis=2).astype(np.float32), (a, b)


@pytest.mark.parametrize("box_size", [40, 120, 300])  # crops that upsample, keep, downsample
def test_crop_pixels_are_the_photograph_at_their_full_image_position(box_size):
    image, (a, b) = ramp(480, 640)
    ids = np.zeros((480, 640), np.uint16)
    ids[100 : 100 + box_size, 150 : 150 + box_size] = 3
    crop = make_crop(image, ids, 3, instance_boxes(ids)[3], size=128, pad=0.1, masked=False)
    v, u = np.mgrid[0:128, 0:128] + 0.5
    full = crop.to_full(np.stack([u.ravel(), v.ravel()], axis=1))
    expected = (a * full[:, 0] + b * full[:, 1]).reshape(128, 128)
    inner = slice(16, 112)  # away from the blur's border
    np.testing.assert_allclose(crop.image[inner, inner, 0], expected[inner, inner], atol=2e-4)
    np.testing.assert_allclose(crop.scale, 128 / (box_size * 1.2))


def test_round_trip_and_mask():
    image, _ = ramp(200, 300)
    ids = np.zeros((200, 300), np.uint16)
    ids[50:90, 60:80] = 1
    ids[120:160, 200:260] = 2
    crops = make_crops(image, ids, size=64, pad=0.25, masked=True)
    assert [c.instance_id for c in crops] == [1, 2]
    points = np.array([[61.3, 52.7], [79.5, 89.5]])
    np.testing.assert_allclose(crops[0].to_full(crops[0].to_crop(points)), points)
    # the mask's area in full-image pixels matches the instance's
    for crop, area in zip(crops, (40 * 20, 40 * 60)):
        assert abs(crop.mask.sum() / crop.scale**2 - area) < 0.05 * area
        assert np.all(crop.image[~crop.mask] == 0)

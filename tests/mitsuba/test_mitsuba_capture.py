"""A capture rendered by Mitsuba 3 (the independent benchmark captures): the same room as our
kernels render it, within the two renderers' noise, with our instance ids beside it."""

import numpy as np

from invrender.mitsuba.capture import mitsuba_capture
from invrender.scene.images import read_image, read_mask
from invrender.synthesize import stage

ROOM = {"cameras": {"count": 2, "width": 40, "height": 30}, "atlas_resolution": 64}


def test_a_mitsuba_capture_matches_ours_and_keeps_the_layout(tmp_path):
    stage.run("room", tmp_path / "mitsuba", ROOM, spp=64, seed=0, renderer_factory=mitsuba_capture)
    stage.run("room", tmp_path / "ours", ROOM, spp=64, seed=0)
    for view in ("view_000", "view_001"):
        theirs = read_image(tmp_path / "mitsuba" / "images" / f"{view}.exr")
        ours = read_image(tmp_path / "ours" / "images" / f"{view}.exr")
        # the mean radiance of the view agrees within 3 % per channel: the same room and light
        np.testing.assert_allclose(theirs.mean((0, 1)), ours.mean((0, 1)), rtol=0.03)
        assert not np.array_equal(theirs, ours)  # another renderer's samples, not ours
        masks = [read_mask(tmp_path / k / "ground_truth" / "masks" / f"{view}.png") for k in ("mitsuba", "ours")]
        np.testing.assert_array_equal(*masks)
    assert (tmp_path / "mitsuba" / "ground_truth" / "scene" / "scene.json").exists()
    assert (tmp_path / "mitsuba" / "sparse" / "cameras.txt").exists()

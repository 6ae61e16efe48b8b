"""The radiance scale from one unit-radiance render: a photo that is s_true times another
(independent seed) unit render gives back s_true within the noise once the render's own variance
is taken out, and the plain fit is measurably shrunk; a light seen directly has radiance 1 on
its room side (the one-sided winding faces the room)."""

import numpy as np
import pytest

from invrender.room_box.box import RoomBox
from invrender.room_lights.lights import ceiling_grid, initial_lights
from invrender.room_lights.radiance import light_scene, radiance_scale, unit_render
from invrender.scene.cameras import pinhole_camera

BOX = RoomBox([0.0, 1.5, 0.0], [4.0, 3.0, 6.0], 0.0)
CAMERA = pinhole_camera("photo", [0.0, 1.5, 2.5], [0.0, 1.5, -2.5], 48, 36, 60.0)


def test_closed_form_is_the_least_squares_minimum():
    rng = np.random.default_rng(0)
    unit, photo = rng.random((6, 5, 3)), rng.random((6, 5, 3))
    mask = rng.random((6, 5)) > 0.3
    s = radiance_scale(unit, photo, mask)
    loss = lambda x: np.sum((x * unit[mask] - photo[mask]) ** 2)  # noqa: E731
    assert loss(s) < min(loss(s * 1.001), loss(s * 0.999))
    with pytest.raises(ValueError, match="black"):
        radiance_scale(np.zeros((2, 2, 3)), photo[:2, :2])


def test_scale_recovered_from_an_independent_render():
    scene = light_scene(BOX, initial_lights(BOX, CAMERA).lights, CAMERA)
    fit, target = unit_render(scene, CAMERA, spp=16, seed=0), unit_render(scene, CAMERA, spp=16, seed=1)
    photo = 3.7 * target["radiance"]
    corrected = radiance_scale(fit["radiance"], photo, variance=fit["variance"])
    plain = radiance_scale(fit["radiance"], photo)
    # Measured: corrected 3.725, plain 3.445 (shrunk by 1 / (1 + var / mu^2), var / mu^2 ~ 0.06).
    assert corrected == pytest.approx(3.7, rel=0.03)
    assert plain < 3.7 * 0.97


def test_lights_emit_unit_radiance_into_the_room():
    # Looking straight up from the floor's centre: the ceiling cells fill the view's middle.
    up = pinhole_camera("up", [0.0, 0.2, 0.0], [0.0, 3.0, 0.0001], 24, 24, 40.0)
    scene = light_scene(BOX, ceiling_grid(BOX, cell=0.5), up)  # 2 x 3 cells, gaps between them
    out = unit_render(scene, up, spp=4, seed=0)
    lit = out["instance_id"] >= 2
    assert lit.mean() > 0.3 and (~lit).any()
    # Away from the edges (the id is the pixel centre's, the radiance the pixel's average):
    inner = lambda m: m[1:-1, 1:-1] & m[:-2, 1:-1] & m[2:, 1:-1] & m[1:-1, :-2] & m[1:-1, 2:]  # noqa: E731
    radiance = out["radiance"][1:-1, 1:-1]
    assert inner(lit).sum() > 50 and inner(~lit).sum() > 20
    np.testing.assert_allclose(radiance[inner(lit)], 1.0, atol=1e-5)  # kd 0: emission only
    assert radiance[inner(~lit)].max() < 0.5  # the grey ceiling between them: reflected light only

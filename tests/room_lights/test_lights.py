"""The initial light set on a known box and camera: counts worked out by hand from the frustum
(4 x 3 x 6 box, 60 degree horizontal field of view, 4:3 image), the frustum test against
sampling each quad and projecting the samples, and a window's quad recovered from its pixels."""

import numpy as np
import pytest

from invrender.room_box.box import RoomBox, cast_box
from invrender.room_lights.lights import (
    LightSettings,
    behind_camera,
    camera_light,
    ceiling_grid,
    in_frustum,
    initial_lights,
    wall_quads,
    window_lights,
)
from invrender.scene.cameras import pinhole_camera, pixel_directions, project_points

BOX = RoomBox([0.0, 1.5, 0.0], [4.0, 3.0, 6.0], 0.0)


def camera_at(z, width=64, height=48):
    return pinhole_camera("photo", [0.0, 1.5, z], [0.0, 1.5, z - 5.0], width, height, 60.0)


def test_ceiling_grid_cells_are_shrunk_and_face_down():
    quads = ceiling_grid(BOX, cell=0.25)  # side 1.5: round(4 / 1.5) = 3 by round(6 / 1.5) = 4
    assert len(quads) == 12
    for q in quads:
        assert q.center[1] == pytest.approx(3.0)
        np.testing.assert_allclose(q.normal, [0, -1, 0])
        assert q.area == pytest.approx((4 / 3 * 0.8) * (6 / 4 * 0.8))
    np.testing.assert_allclose(sorted({round(q.center[0], 6) for q in quads}), [-4 / 3, 0, 4 / 3], atol=1e-5)


def test_counts_camera_near_the_back_wall():
    # At z = 2.5 the frustum's top reaches the ceiling (y = 3) beyond 3.46 ahead (z < -0.96): the
    # two far rows of cells (z centres -2.25, -0.75) are seen, the near two are not and are not
    # wholly behind the camera. Walls -z, +x, -x are seen; +z (behind) is not.
    lights = initial_lights(BOX, camera_at(2.5), LightSettings(cell=0.25))
    kinds = [q.kind for q in lights.lights]
    assert lights.culled == {"in_frustum": 6, "behind_camera": 0}
    assert kinds.count("ceiling") == 6 and kinds.count("camera") == 1
    assert [q.name for q in lights.lights if q.kind == "wall"] == ["wall_+z"]


def test_counts_camera_in_the_middle():
    # At z = 0 the two rows behind the image plane are culled; the frustum reaches the ceiling only
    # beyond 3.46 ahead but the far wall is 3 ahead, so no cell is seen, and the side walls (x = 2
    # seen only beyond 3.46 ahead) are invisible too: three wall lights.
    lights = initial_lights(BOX, camera_at(0.0), LightSettings(cell=0.25))
    assert lights.culled == {"in_frustum": 0, "behind_camera": 6}
    assert sorted(q.name for q in lights.lights if q.kind == "wall") == ["wall_+x", "wall_+z", "wall_-x"]
    assert len(lights.lights) == 6 + 1 + 3


def _sampled_visible(quad, camera, n=40):
    a, b = np.meshgrid(np.linspace(-0.5, 0.5, n), np.linspace(-0.5, 0.5, n))
    points = quad.center + a.reshape(-1, 1) * quad.e1 + b.reshape(-1, 1) * quad.e2
    points = points[points @ camera.R[2] + camera.t[2] > 1e-9]  # in front of the camera only
    uv = project_points(camera, points)
    return bool(np.any((uv[:, 0] >= 0) & (uv[:, 0] <= camera.width) & (uv[:, 1] >= 0) & (uv[:, 1] <= camera.height)))


@pytest.mark.parametrize("z, yaw", [(2.5, 0.0), (1.0, 0.0), (0.0, 0.0), (-1.0, 0.0), (1.0, 30.0), (0.0, -70.0)])
def test_frustum_test_agrees_with_projected_samples(z, yaw):
    camera = camera_at(z)
    box = RoomBox(BOX.center, BOX.size, yaw)
    for quad in ceiling_grid(box, cell=0.15) + wall_quads(box):
        assert in_frustum(quad, camera) == _sampled_visible(quad, camera), quad.name


def test_behind_camera_and_camera_light():
    camera = camera_at(0.0)
    rows = {round(q.center[2], 6): behind_camera(q, camera) for q in ceiling_grid(BOX, cell=0.25)}
    assert rows == {-2.25: False, -0.75: False, 0.75: True, 2.25: True}
    light = camera_light(BOX, camera, size=0.5, offset=0.05)
    np.testing.assert_allclose(light.normal, [0, 0, -1], atol=1e-12)
    np.testing.assert_allclose(light.center, [0, 1.5, 0.3], atol=1e-12)  # 0.05 * 6 behind
    assert light.area == pytest.approx(2.0 * 1.5)  # half of 4 wide by half of 3 high
    # Against the back wall it stays inside the box.
    assert camera_light(BOX, camera_at(2.95), offset=0.05).center[2] < 3.0


def test_window_quad_from_its_pixels_and_lamps_marked():
    camera = camera_at(2.5, 160, 120)
    face, depth = cast_box(BOX, camera)
    points = camera.center + pixel_directions(camera) * depth[..., None]
    window = (np.abs(points[..., 0]) < 1.0) & (np.abs(points[..., 1] - 1.5) < 0.5) & (points[..., 2] < -2.99)
    segments = np.where(window, 1, 0)
    segments[-5:, :5] = 2  # a lamp's pixels, on the floor: an object's (room_objects places it)
    quads, lamps = window_lights(
        BOX, camera, segments, {1: ("window", "window_0"), 2: ("lamp", "lamp_a"), 3: ("wall", "w")}
    )
    assert lamps == [{"segment": 2, "name": "lamp_a"}]
    (q,) = quads
    assert q.kind == "window" and q.name == "window_0"
    np.testing.assert_allclose(q.normal, [0, 0, 1], atol=1e-12)
    pixel = 5.5 / 80 * (2.5 + 3.0) * np.tan(np.radians(30))  # about one pixel's footprint on the wall
    np.testing.assert_allclose(q.center, [0, 1.5, -3.0], atol=pixel)
    np.testing.assert_allclose(sorted(np.abs(q.e1 + q.e2))[1:], [1.0, 2.0], atol=2 * pixel)


def test_a_lamp_on_the_ceiling_is_a_panel_of_its_pixels_footprint():
    """A lamp segment whose rays hit the ceiling (a flush panel: no asset for room_objects) becomes
    an emissive quad on the ceiling: its footprint from the pixels, just below the ceiling."""
    camera = pinhole_camera("photo", [0.0, 1.5, 2.5], [0.0, 2.0, -2.5], 160, 120, 60.0)
    face, depth = cast_box(BOX, camera)
    points = camera.center + pixel_directions(camera) * depth[..., None]
    panel = (np.abs(points[..., 0] - 0.5) < 0.4) & (np.abs(points[..., 2] + 1.0) < 0.6) & (points[..., 1] > 2.99)
    assert panel.sum() > 50
    quads, lamps = window_lights(BOX, camera, np.where(panel, 7, 0), {7: ("lamp", "panel")}, inset=1e-3)
    assert lamps == []
    (q,) = quads
    assert q.kind == "lamp" and q.name == "panel"
    np.testing.assert_allclose(q.normal, [0, -1, 0], atol=1e-12)
    # the truth: the bounding rectangle of the panel's points seen (cast_box, the room box's own
    # ray caster), within about a pixel's footprint there
    seen = points[panel]
    pixel = 2 * np.tan(np.radians(30)) / 160 * np.linalg.norm(seen.mean(0) - camera.center)
    lo, hi = seen.min(0), seen.max(0)
    np.testing.assert_allclose(q.center, [(lo[0] + hi[0]) / 2, 3.0 - 3e-3, (lo[2] + hi[2]) / 2], atol=pixel)
    np.testing.assert_allclose(np.abs(q.e1 + q.e2)[[0, 2]], (hi - lo)[[0, 2]], atol=2 * pixel)

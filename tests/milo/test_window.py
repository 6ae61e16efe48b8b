"""Windows found in the photographs (milo/window.py): on a room with a window onto sun and sky,
the texels found against the truth's kw and the sky they show against the truth's kg; on the same
room at night, none; the pairing statistic and the rays beyond a surface against hand-made
cases."""

import numpy as np
import pytest
from milo_capture import WINDOW_ROOM, build_capture

from invrender.bench.milo_independent import DARK, truth_maps
from invrender.milo.config import resolve
from invrender.milo.importance import TexelPixels
from invrender.milo.stage import training_features
from invrender.milo.window import Beyond, Views, find_windows, pair_difference
from invrender.render.renderer import Renderer
from invrender.scene.atlas import AtlasTexels
from invrender.scene.cameras import pinhole_camera, read_cameras
from invrender.scene.capture import read_view
from invrender.scene.cubemap import as_cube
from invrender.scene.mesh_io import read_mesh
from invrender.scene.types import Maps, Scene

NIGHT = {**WINDOW_ROOM, "environment": DARK}


def windows_of(root):
    """find_windows on the capture at `root`, as the milo stage calls it, and its texel pixels."""
    settings = resolve("texels")
    atlas = AtlasTexels.load(root / "geometry" / "atlas.npz")
    cameras = read_cameras(root / "cameras")
    images = [read_view(root / "cameras" / "images", c) for c in cameras]
    scene = Scene(read_mesh(root / "geometry" / "mesh.ply"), Maps.uniform(size=atlas.shape, cube=16), cameras)
    pixels = TexelPixels.build(atlas, Renderer(scene, training_features(settings)), cameras)
    return find_windows(pixels, images, cameras, settings["sky_resolution"]), pixels


def test_the_window_is_found_and_the_sky_it_shows_is_the_truths(window_room):
    root = window_room
    windows, pixels = windows_of(root)
    assert windows is not None
    truth = truth_maps(root)
    window = truth.kw[pixels.rows, pixels.cols] > 0.5
    found = windows.texels[pixels.rows, pixels.cols]
    seen_by_views = pixels.project([np.ones((c.height, c.width, 3)) for c in read_cameras(root / "cameras")])[1]
    seen_window = window & (seen_by_views[pixels.rows, pixels.cols] >= 3)
    assert (found & seen_window).sum() >= 0.8 * seen_window.sum()  # most of what three views see
    assert (found & ~window).sum() <= 0.05 * found.sum()  # and little of the wall around it
    sky = as_cube(truth.kg).reshape(-1, 3)[windows.seen]
    np.testing.assert_allclose(np.median(windows.sky[windows.seen] / sky, axis=0), 1.0, atol=0.03)
    assert np.abs(windows.sky[windows.seen] - sky).max(1).mean() < 0.05 * sky.mean()


def test_a_room_whose_window_shows_nothing_has_none(tmp_path):
    windows, _ = windows_of(build_capture(tmp_path, NIGHT, spp=16))
    assert windows is None


def test_views_agree_by_direction_through_a_window_and_by_texel_on_a_wall():
    """Twelve texels seen by twelve views: through a window each view's value is its
    direction's, on a wall each texel's."""
    texel, view = np.repeat(np.arange(12), 12), np.tile(np.arange(12), 12)
    direction = (texel + view) % 12  # every direction seen through several texels
    sky, wall = np.log(np.linspace(0.2, 2.0, 12)), np.log(np.linspace(0.3, 0.9, 12))
    window_views = Views(texel, view, np.zeros((144, 3)), sky[direction], direction)
    wall_views = Views(texel, view, np.zeros((144, 3)), wall[texel], direction)
    assert pair_difference(window_views, direction, texel) == pytest.approx(0.0)
    assert pair_difference(window_views, texel, view) > 0.3
    assert pair_difference(wall_views, texel, view) == pytest.approx(0.0)
    assert pair_difference(wall_views, direction, texel) > 0.2


def test_the_rays_through_a_window_leave_the_room_and_those_into_a_table_meet_the_floor():
    """A floor, a wall and a table top as points 5 cm apart; two views: the rays through a patch
    of the wall go on outside, those into the table's top (a mirror of the sky would agree by
    direction too) meet the floor under it."""
    g = np.arange(-1.0, 1.0001, 0.05)
    floor = np.stack(np.meshgrid(g, [0.0], g, indexing="ij"), -1).reshape(-1, 3)
    wall = np.stack(np.meshgrid(g, g + 1.0, [-1.0], indexing="ij"), -1).reshape(-1, 3)
    top = floor[(np.abs(floor[:, 0]) < 0.3) & (np.abs(floor[:, 2]) < 0.3)] + [0.0, 0.7, 0.0]
    points = np.concatenate([floor, wall, top])
    cameras = [
        pinhole_camera(f"v{i}", eye, (0.0, 0.8, -0.5), 32, 24, 60.0)
        for i, eye in enumerate([(0.5, 1.5, 0.9), (-0.5, 1.4, 0.8)])
    ]
    beyond = Beyond(points)

    def views_of(texels):
        texel, view = np.repeat(texels, 2), np.tile([0, 1], len(texels))
        return Views(texel, view, np.zeros((len(texel), 3)), np.zeros(len(texel)), np.zeros(len(texel), int))

    in_wall = np.flatnonzero((np.abs(points[:, 2] + 1.0) < 1e-9) & (np.abs(points[:, 0]) < 0.4))
    in_wall = in_wall[(points[in_wall, 1] > 1.2) & (points[in_wall, 1] < 1.8)]
    in_top = np.arange(len(floor) + len(wall), len(points))
    assert beyond.leaving(views_of(in_wall), cameras) == 1.0
    assert beyond.leaving(views_of(in_top), cameras) == 0.0

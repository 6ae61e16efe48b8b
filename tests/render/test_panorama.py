"""Panoramas as six cube-face pinhole cameras: rendered, they see every direction of the sky
once, each pixel exactly the kg texel of its direction."""

import numpy as np

from invrender.render.features import Features
from invrender.render.renderer import Renderer
from invrender.scene.cameras import cube_face_cameras
from invrender.scene.cubemap import cube_texel, direction_to_cube, lookup_cube
from invrender.scene.types import Maps, Mesh, Scene


def test_cube_face_cameras_see_the_sky_texel_of_every_pixel_direction():
    rng = np.random.default_rng(0)
    maps = Maps.uniform(size=(2, 2), kg=0.0, cube=8)
    maps.kg[:] = rng.uniform(0.1, 2.0, maps.kg.shape)
    far_triangle = Mesh(
        np.array([[1e4, 1e4, 1e4], [1e4 + 1, 1e4, 1e4], [1e4, 1e4 + 1, 1e4]], np.float32),
        np.array([[0, 1, 2]], np.int32),
        np.zeros((3, 2), np.float32),
    )
    center = np.array([0.3, -0.2, 0.1])
    cameras = cube_face_cameras(center, size=32)
    scene = Scene(far_triangle, maps, cameras)
    features = Features.only(max_bounces=0, environment=True)
    renderer = Renderer(scene, features)
    for camera in cameras:
        assert np.isclose(np.linalg.det(camera.R), 1.0)
        out = renderer.render(camera, spp=1, seed=0)
        # 8 kg texels across a 32-pixel face: texel edges fall on pixel edges, so wherever the
        # jittered sample lands in a pixel it sees the texel of the pixel's centre
        ys, xs = np.mgrid[0:32, 0:32] + 0.5
        d_cam = np.stack([(xs - 16) / 16, (ys - 16) / 16, np.ones_like(xs)], -1)
        d_world = d_cam @ camera.R  # R^T d_cam for each pixel
        want = lookup_cube(maps.kg, d_world)
        inside = np.all(np.isclose(out["radiance"], want, rtol=1e-6), axis=-1)
        assert inside.all(), f"{camera.name}: {inside.mean():.0%} of pixels see their texel"
    # together the faces see every texel of the sky
    seen = set()
    for camera in cameras:
        ys, xs = np.mgrid[0:32, 0:32] + 0.5
        d = np.stack([(xs - 16) / 16, (ys - 16) / 16, np.ones_like(xs)], -1) @ camera.R
        face, s, t = direction_to_cube(d.reshape(-1, 3))
        row, col = cube_texel(s, t, 8)
        seen |= set(zip(face.tolist(), row.tolist(), col.tolist()))
    assert len(seen) == 6 * 8 * 8

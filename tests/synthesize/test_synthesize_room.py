"""synthesize.room: orientation, materials looked up through the UVs, atlas, cameras, seed."""

import json

import numpy as np
import pytest

from invrender.scene.atlas import dilate, rasterize_atlas, texel_index
from invrender.scene.cameras import project_points
from invrender.assets.primitives import face_normals, signed_volume
from invrender.synthesize.room import make_room, sky_cube_map


@pytest.fixture(scope="module")
def room():
    return make_room()


def part_faces(metadata, name):
    start, stop = next(p["faces"] for p in metadata["parts"] if p["name"] == name)
    return np.arange(start, stop)


def centroid_lookup(scene, faces=None):
    """Each triangle's maps at its centroid, read the renderer's way (nearest texel)."""
    mesh = scene.mesh
    faces = np.arange(len(mesh.faces)) if faces is None else faces
    row, col = texel_index(mesh.uvs[mesh.faces[faces]].mean(axis=1), scene.maps.atlas_shape)
    m = scene.maps
    return {name: getattr(m, name)[row, col] for name in ("kd", "ks", "ka", "ke", "kw")}


def test_default_room_is_small(room):
    scene, meta = room
    assert 1000 <= scene.mesh.triangle_count <= 6000
    assert scene.maps.atlas_shape == (256, 256)
    assert 16 <= scene.maps.kg.shape[1] <= 32 and scene.maps.kg.shape[0] == 6
    assert len(scene.cameras) == 6 and (scene.cameras[0].width, scene.cameras[0].height) == (96, 72)
    json.dumps(meta, allow_nan=False)  # metadata goes into scene.json


def test_shell_faces_the_interior(room):
    scene, meta = room
    mesh = scene.mesh
    shell = mesh.instance_ids == 0
    lo, hi = np.array(meta["room_bounds"])
    # Floor, walls, ceiling, window and lights close the box: fronts inwards = negative volume.
    assert signed_volume(mesh.positions, mesh.faces[shell]) == pytest.approx(-np.prod(hi - lo), rel=1e-5)
    centroids = mesh.positions[mesh.faces[shell]].mean(axis=1)
    inward = np.einsum("ij,ij->i", face_normals(mesh.positions, mesh.faces[shell]), (lo + hi) / 2 - centroids)
    assert np.all(inward > 0)


@pytest.mark.parametrize("name", ["cabinet", "crate"])
def test_furniture_boxes_face_outwards(room, name):
    scene, meta = room
    faces = scene.mesh.faces[part_faces(meta, name)]
    corners = scene.mesh.positions[faces]
    centre = (corners.reshape(-1, 3).min(0) + corners.reshape(-1, 3).max(0)) / 2
    outward = np.einsum("ij,ij->i", face_normals(scene.mesh.positions, faces), corners.mean(axis=1) - centre)
    assert np.all(outward > 0)


def test_instance_ids(room):
    scene, meta = room
    ids = scene.mesh.instance_ids
    for part in meta["parts"]:
        start, stop = part["faces"]
        assert np.all(ids[start:stop] == part["instance_id"])
    assert sorted(np.unique(ids)) == list(range(len(meta["config"]["furniture"]) + 1))


def test_only_window_and_light_triangles_emit(room):
    scene, meta = room
    look = centroid_lookup(scene)
    window = np.zeros(scene.mesh.triangle_count, bool)
    window[part_faces(meta, "window")] = True
    light = np.zeros_like(window)
    for p in meta["parts"]:
        if p["emitter"]:
            light[p["faces"][0] : p["faces"][1]] = True
    assert window.sum() > 0 and light.sum() > 0
    assert np.all(look["kw"][window] == 1) and np.all(look["kw"][~window] == 0)
    assert np.all(look["ke"][light] > 0) and np.all(look["ke"][~light] == 0)
    emitting = window | light
    assert np.all(look["kd"][emitting] == 0) and np.all(look["ks"][emitting] == 0)
    lum = look["ke"][light].mean(axis=1)
    assert 5 <= lum.min() and lum.max() <= 20 and lum.max() > 1.3 * lum.min()  # a spatial pattern


def test_materials(room):
    scene, meta = room
    look = centroid_lookup(scene)
    table = part_faces(meta, "table")
    assert np.all((look["ks"][table] >= 0.3) & (look["ks"][table] <= 0.6))
    assert np.all((look["ka"][table] >= 0.01) & (look["ka"][table] <= 0.05))
    plain = np.ones(scene.mesh.triangle_count, bool)
    plain[table] = False
    for p in meta["parts"]:
        if p["emitter"] or p["window"]:
            plain[p["faces"][0] : p["faces"][1]] = False
    np.testing.assert_allclose(look["ks"][plain], 0.04, atol=1e-6)
    np.testing.assert_allclose(look["ka"][plain], 0.3, atol=1e-6)
    # Textured: the floor varies, and differs from the walls.
    floor, wall = look["kd"][part_faces(meta, "floor")], look["kd"][part_faces(meta, "wall")]
    assert floor.std(axis=0).max() > 0.02 and wall.std(axis=0).max() > 0.02
    assert np.abs(floor.mean(0) - wall.mean(0)).max() > 0.1
    assert scene.maps.kd.max() <= 1 and scene.maps.kd.min() >= 0 and scene.maps.ka.min() > 0


def test_every_centroid_texel_is_covered_or_dilated(room):
    scene, meta = room
    texels = rasterize_atlas(scene.mesh, *scene.maps.atlas_shape)
    _, grown = dilate(np.zeros(texels.shape), texels.mask, meta["atlas"]["padding"])
    row, col = texel_index(scene.mesh.uvs[scene.mesh.faces].mean(axis=1), texels.shape)
    assert grown[row, col].all()
    # Covered texels hold a point of their own triangle's part: the kd there was evaluated for it.
    assert texels.mask.mean() > 0.5


def test_environment_sky_ground_sun(room):
    scene, meta = room
    from invrender.scene.cubemap import cube_to_direction

    kg = scene.maps.kg
    n = kg.shape[1]
    face = np.repeat(np.arange(6), n * n).reshape(6, n, n)
    rows, cols = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    d = cube_to_direction(face, (cols + 0.5) / n, (rows + 0.5) / n)
    lum = kg.mean(-1)
    sun = lum > 20
    assert 1 <= sun.sum() <= 6  # a small bright region
    env = meta["config"]["environment"]
    el, az = np.radians(env["sun_elevation_deg"]), np.radians(env["sun_azimuth_deg"])
    sun_dir = np.array([np.cos(el) * np.sin(az), np.sin(el), -np.cos(el) * np.cos(az)])
    assert np.all(d[sun] @ sun_dir > np.cos(np.radians(10)))
    sky, ground = lum[(d[..., 1] > 0.2) & ~sun], lum[d[..., 1] < -0.2]
    assert sky.min() > ground.max()
    # The zenith is bluer than the horizon: a gradient.
    zenith = kg[d[..., 1] > 0.95].mean(0)
    assert zenith[2] > zenith[0]


def test_cameras_look_into_the_room(room):
    scene, meta = room
    lo, hi = np.array(meta["room_bounds"])
    centre = (lo + hi) / 2
    for cam in scene.cameras:
        R = cam.R
        np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1)
        assert np.all(cam.center > lo) and np.all(cam.center < hi)
        assert R[1] @ [0, 1, 0] < 0  # OpenCV: image y points down, world +Y up
        ((u, v),) = project_points(cam, centre[None])
        assert 0 < u < cam.width and 0 < v < cam.height
        fov = 2 * np.degrees(np.arctan(cam.width / 2 / cam.focal[0]))
        assert 60 <= fov <= 70 and cam.model == "PINHOLE"
    # They look around: view directions spread over the compass.
    forward = np.array([c.R[2] for c in scene.cameras])
    heading = np.degrees(np.arctan2(forward[:, 0], forward[:, 2]))
    assert np.ptp(np.sort(heading)) > 180


def test_seed_determines_everything():
    a, meta_a = make_room({"seed": 3, "atlas_resolution": 128})
    b, meta_b = make_room({"seed": 3, "atlas_resolution": 128})
    c, _ = make_room({"seed": 4, "atlas_resolution": 128})
    for name in ("positions", "faces", "uvs", "instance_ids"):
        np.testing.assert_array_equal(getattr(a.mesh, name), getattr(b.mesh, name))
    for name in ("kd", "ks", "ka", "ke", "kw", "kg"):
        np.testing.assert_array_equal(getattr(a.maps, name), getattr(b.maps, name))
    for ca, cb in zip(a.cameras, b.cameras):
        np.testing.assert_array_equal(ca.R, cb.R)
        np.testing.assert_array_equal(ca.t, cb.t)
    assert meta_a == meta_b
    assert a.maps.atlas_shape == (128, 128)
    assert not np.array_equal(a.cameras[0].t, c.cameras[0].t)
    assert not np.array_equal(a.mesh.positions, c.mesh.positions)  # furniture moved


def test_bad_config_names_the_key():
    with pytest.raises(ValueError, match="windw"):
        make_room({"windw": {}})
    with pytest.raises(ValueError, match="window"):
        make_room({"window": {"center": [5.0, 1.0]}})


def test_sky_size_is_configurable():
    assert sky_cube_map({**make_room.__globals__["ENVIRONMENT_DEFAULTS"], "size": 24}).shape == (6, 24, 24, 3)

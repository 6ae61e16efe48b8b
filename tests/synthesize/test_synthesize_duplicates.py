"""synthesize.duplicates: true poses, shared object and atlas, camera, seed."""

import json

import numpy as np
import pytest

from invrender.scene.atlas import texel_index
from invrender.scene.cameras import project_points
from invrender.synthesize.duplicates import _label, build_object, make_duplicates, object_mesh
from invrender.synthesize.primitives import signed_volume


@pytest.fixture(scope="module")
def dup():
    return make_duplicates()


def poses_of(meta):
    return [np.array(p["T_obj2world"]) for p in meta["poses"]["instances"]]


def test_defaults(dup):
    scene, meta = dup
    assert len(meta["poses"]["instances"]) == 6 == len(meta["copies"])
    assert len(scene.cameras) == 1 and (scene.cameras[0].width, scene.cameras[0].height) == (96, 72)
    assert scene.maps.atlas_shape == (256, 256)
    json.dumps(meta, allow_nan=False)


def test_poses_json_form(dup):
    _, meta = dup
    poses = meta["poses"]
    assert set(poses) >= {"convention", "instances"} and "scale" in poses
    for i, inst in enumerate(poses["instances"], 1):
        assert set(inst) == {"instance_id", "mask_value", "registered", "T_obj2world"}
        assert inst["instance_id"] == inst["mask_value"] == i and inst["registered"] is True
        assert np.shape(inst["T_obj2world"]) == (4, 4)


def test_poses_are_rigid_transforms(dup):
    _, meta = dup
    for T in poses_of(meta):
        R = T[:3, :3]
        np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-12)
        assert np.linalg.det(R) == pytest.approx(1.0)
        np.testing.assert_array_equal(T[3], [0, 0, 0, 1])


def test_placing_the_object_by_the_poses_reproduces_the_mesh(dup):
    scene, meta = dup
    obj = build_object(meta["config"])  # built independently of the scene
    corners = obj.positions[obj.faces]  # (F, 3, 3), object frame
    mesh = scene.mesh
    for copy, T in zip(meta["copies"], poses_of(meta)):
        f0, f1 = copy["faces"]
        placed = corners @ T[:3, :3].T + T[:3, 3]
        np.testing.assert_allclose(mesh.positions[mesh.faces[f0:f1]], placed, atol=1e-5)
        assert np.all(mesh.instance_ids[f0:f1] == copy["instance_id"])
    f0, f1 = meta["floor"]["faces"]
    assert np.all(mesh.instance_ids[f0:f1] == 0)


def test_object_faces_outwards(dup):
    scene, meta = dup
    obj = build_object(meta["config"])
    assert signed_volume(obj.positions, obj.faces) > 0
    for copy in meta["copies"]:
        f0, f1 = copy["faces"]
        assert signed_volume(scene.mesh.positions, scene.mesh.faces[f0:f1]) > 0


def test_copies_share_one_object_atlas_region(dup):
    scene, meta = dup
    uvs = [scene.mesh.uvs[c["vertices"][0] : c["vertices"][1]] for c in meta["copies"]]
    for other in uvs[1:]:
        np.testing.assert_array_equal(other, uvs[0])
    # The floor's UVs do not overlap the object's texels.
    f0, f1 = meta["floor"]["faces"]
    floor_uv = scene.mesh.uvs[scene.mesh.faces[f0:f1]].reshape(-1, 2)
    lo, hi = uvs[0].min(0), uvs[0].max(0)
    obj_rows, obj_cols = texel_index(uvs[0], scene.maps.atlas_shape)
    floor_rows, floor_cols = texel_index(floor_uv, scene.maps.atlas_shape)
    assert not set(zip(obj_rows, obj_cols)) & set(zip(floor_rows, floor_cols))
    # The object gets a fair share of the atlas despite its small area.
    assert (hi - lo).prod() > 0.1


def test_object_mesh_round_trip(dup):
    scene, meta = dup
    obj = build_object(meta["config"])
    for i in (1, 4):
        m = object_mesh(scene, meta, i)
        np.testing.assert_allclose(m.positions[m.faces], obj.positions[obj.faces], atol=1e-5)


def test_copies_rest_on_or_above_the_floor_apart(dup):
    scene, meta = dup
    max_lift = meta["config"]["placement"]["max_lift"]
    centres = []
    for copy in meta["copies"]:
        v0, v1 = copy["vertices"]
        y = scene.mesh.positions[v0:v1, 1]
        assert -1e-5 <= y.min() <= max_lift + 1e-5
        centres.append(scene.mesh.positions[v0:v1].mean(0))
    c = np.array(centres)
    d = np.linalg.norm(c[:, None, [0, 2]] - c[None, :, [0, 2]], axis=-1) + np.eye(len(c)) * 1e9
    assert d.min() > 0.1  # bounding spheres of a 6.6 x 12.2 cm can do not overlap


def test_camera_sees_every_copy(dup):
    scene, meta = dup
    cam = scene.cameras[0]
    assert cam.R[2] @ [0, -1, 0] > 0.5  # looking down
    for T in poses_of(meta):
        ((u, v),) = project_points(cam, T[None, :3, 3])
        assert 0 < u < cam.width and 0 < v < cam.height


def test_label_has_no_rotational_symmetry(dup):
    _, meta = dup
    r, h = meta["config"]["object"]["radius"], meta["config"]["object"]["height"]
    phi = np.linspace(0, 2 * np.pi, 180, endpoint=False)
    y = np.linspace(-h / 2, h / 2, 60)
    P, Y = np.meshgrid(phi, y, indexing="ij")
    pos = np.stack([r * np.cos(P), Y, -r * np.sin(P)], -1).reshape(-1, 3)
    img = _label(r, h)(pos, None).reshape(180, 60, 3)
    for shift in range(1, 180):  # rotations by 2 .. 358 degrees about the axis
        change = np.abs(np.roll(img, shift, axis=0) - img).mean()
        assert change > (0.02 if 10 <= shift <= 170 else 0.005)
    # And it is what the maps hold: label texels are not uniform.
    scene, _ = dup
    f0, f1 = meta["copies"][0]["faces"]
    rows, cols = texel_index(scene.mesh.uvs[scene.mesh.faces[f0:f1]].mean(1), scene.maps.atlas_shape)
    assert scene.maps.kd[rows, cols].std(0).max() > 0.1


def test_seed_determines_everything():
    a, meta_a = make_duplicates({"seed": 7, "count": 3, "atlas_resolution": 128})
    b, meta_b = make_duplicates({"seed": 7, "count": 3, "atlas_resolution": 128})
    c, meta_c = make_duplicates({"seed": 8, "count": 3, "atlas_resolution": 128})
    assert meta_a == meta_b and len(meta_a["copies"]) == 3
    np.testing.assert_array_equal(a.mesh.positions, b.mesh.positions)
    np.testing.assert_array_equal(a.maps.kd, b.maps.kd)
    assert meta_a["poses"] != meta_c["poses"]


def test_impossible_placement_says_so():
    with pytest.raises(ValueError, match="placement"):
        make_duplicates({"count": 40, "placement": {"attempts": 200}})

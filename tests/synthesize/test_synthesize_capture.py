"""synthesize.capture: the capture directory, with a fake renderer and with the real one."""

import json

import numpy as np
import pytest

from invrender.scene.atomic import MARKER
from invrender.scene.cameras import read_colmap
from invrender.scene.format import load_scene
from invrender.scene.images import read_image, read_mask
from invrender.scene.mesh_io import read_mesh
from invrender.synthesize import make_duplicates, make_room, write_capture
from invrender.synthesize import run as synthesize

SMALL_ROOM = {"atlas_resolution": 64, "cameras": {"count": 2, "width": 32, "height": 24}}
SMALL_DUPLICATES = {"count": 3, "atlas_resolution": 64, "camera": {"width": 48, "height": 36}}


class FakeRenderer:
    """Arrays of the right shape: radiance from the pixel position, ids in stripes."""

    def __init__(self, scene, fail_at=None, bad_shape=False):
        self.ids = np.unique(scene.mesh.instance_ids)
        self.calls, self.fail_at, self.bad_shape = [], fail_at, bad_shape

    def render(self, camera, spp=64, seed=0):
        self.calls.append((camera.name, spp, seed))
        if self.fail_at is not None and len(self.calls) > self.fail_at:
            raise RuntimeError("device lost")
        h, w = camera.height, camera.width
        ys, xs = np.mgrid[0:h, 0:w]
        radiance = np.stack([xs / w, ys / h, np.full((h, w), 0.5)], -1).astype(np.float32) * 3
        ids = self.ids[(xs // 4) % len(self.ids)].astype(np.int32)
        if self.bad_shape:
            radiance = radiance[:, :-1]
        return {
            "radiance": radiance,
            "depth": np.ones((h, w), np.float32),
            "instance_id": ids,
            "triangle_id": np.zeros((h, w), np.int32),
        }


def test_room_capture_layout(tmp_path):
    scene, meta = make_room(SMALL_ROOM)
    renderers = []

    def factory(s):
        renderers.append(FakeRenderer(s))
        return renderers[0]

    out = tmp_path / "capture"
    write_capture(scene, meta, out, renderer_factory=factory, spp=8, seed=5)
    assert [c[1:] for c in renderers[0].calls] == [(8, 5), (8, 5)]
    names = [c.name for c in scene.cameras]
    assert names == ["view_000.exr", "view_001.exr"]
    fake = FakeRenderer(scene)
    for cam in scene.cameras:
        stem = cam.name[:-4]
        expected = fake.render(cam)
        np.testing.assert_array_equal(read_image(out / "images" / f"{stem}.exr"), expected["radiance"])
        assert (out / "images" / f"{stem}.png").is_file()
        mask = read_mask(out / "ground_truth" / "masks" / f"{stem}.png")
        assert mask.dtype == np.uint16
        np.testing.assert_array_equal(mask, expected["instance_id"])
    cams = read_colmap(out / "sparse")
    assert [c.name for c in cams] == names
    for got, want in zip(cams, scene.cameras):
        np.testing.assert_allclose(got.R, want.R, atol=1e-9)
        np.testing.assert_allclose(got.t, want.t, atol=1e-9)
        np.testing.assert_allclose(got.params, want.params)
    # mesh.ply: geometry only, welded, same triangles in the same order.
    user_mesh = read_mesh(out / "mesh.ply", require_uvs=False)
    assert user_mesh.uvs is None
    assert len(user_mesh.positions) < len(scene.mesh.positions)
    np.testing.assert_array_equal(user_mesh.positions[user_mesh.faces], scene.mesh.positions[scene.mesh.faces])
    truth = load_scene(out / "ground_truth" / "scene")
    np.testing.assert_array_equal(truth.maps.kd, scene.maps.kd)
    np.testing.assert_array_equal(truth.maps.kg, scene.maps.kg)
    np.testing.assert_array_equal(truth.mesh.instance_ids, scene.mesh.instance_ids)
    doc = json.loads((out / "ground_truth" / "scene" / "scene.json").read_text())
    assert doc["metadata"]["kind"] == "room"
    assert not (out / "ground_truth" / "poses.json").exists()
    # The capture proper holds only what a user would bring: the true masks are truth.
    assert sorted(p.name for p in out.iterdir()) == [MARKER, "ground_truth", "images", "mesh.ply", "sparse"]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["capture"]


def test_duplicates_capture_has_poses_and_object(tmp_path):
    scene, meta = make_duplicates(SMALL_DUPLICATES)
    out = tmp_path / "capture"
    write_capture(scene, meta, out, renderer_factory=FakeRenderer, spp=4)
    poses = json.loads((out / "ground_truth" / "poses.json").read_text())
    assert poses == meta["poses"]
    obj = read_mesh(out / "ground_truth" / "object.ply")
    assert len(obj.faces) == meta["object"]["face_count"]
    T = np.array(poses["instances"][1]["T_obj2world"])
    f0, f1 = meta["copies"][1]["faces"]
    np.testing.assert_allclose(
        obj.positions[obj.faces] @ T[:3, :3].T + T[:3, 3], scene.mesh.positions[scene.mesh.faces[f0:f1]], atol=1e-5
    )
    assert read_mask(out / "ground_truth" / "masks" / "view_000.png").max() == 3


def test_failed_render_leaves_nothing(tmp_path):
    scene, meta = make_room(SMALL_ROOM)
    out = tmp_path / "capture"
    with pytest.raises(RuntimeError, match="device lost"):
        write_capture(scene, meta, out, renderer_factory=lambda s: FakeRenderer(s, fail_at=1))
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(RuntimeError, match="radiance"):
        write_capture(scene, meta, out, renderer_factory=lambda s: FakeRenderer(s, bad_shape=True))
    assert list(tmp_path.iterdir()) == []


def test_real_renderer_masks_match_the_mesh(tmp_path):
    """With the OpenCL renderer: the mask is the instance id of the triangle each pixel sees,
    and every copy shows up."""
    from invrender.render import Renderer
    from invrender.render.analysis import analyse

    scene, meta = make_duplicates(SMALL_DUPLICATES)
    renderer = Renderer(scene, analyse(scene))
    out = renderer.render(scene.cameras[0], spp=4, seed=0)
    tri, ids = out["triangle_id"], out["instance_id"]
    hit = tri >= 0
    np.testing.assert_array_equal(ids[hit], scene.mesh.instance_ids[tri[hit]])
    assert set(np.unique(ids)) == {0, 1, 2, 3}
    assert np.isfinite(out["radiance"]).all() and out["radiance"].mean() > 0

    metadata = synthesize(
        "duplicates", tmp_path / "capture", SMALL_DUPLICATES, spp=4, renderer_factory=lambda s: renderer
    )
    np.testing.assert_array_equal(read_mask(tmp_path / "capture" / "ground_truth" / "masks" / "view_000.png"), ids)
    assert metadata["poses"] == meta["poses"]


def test_real_renderer_sees_the_baked_emission():
    """Pixels well inside a ceiling light show the ke the maps hold at the uv the renderer
    reports there (kd = ks = 0, so nothing is reflected): the atlas convention is the renderer's."""
    from scipy.ndimage import binary_erosion

    from invrender.render import Renderer
    from invrender.render.analysis import analyse
    from invrender.scene.atlas import texel_index

    scene, meta = make_room({"atlas_resolution": 128, "cameras": {"count": 2, "width": 48, "height": 36}})
    emitter = np.zeros(scene.mesh.triangle_count, bool)
    for p in meta["parts"]:
        if p["emitter"]:
            emitter[p["faces"][0] : p["faces"][1]] = True
    out = Renderer(scene, analyse(scene)).render(scene.cameras[1], spp=16, seed=0)  # odd views look up
    tri = out["triangle_id"]
    on_light = np.zeros(tri.shape, bool)
    on_light[tri >= 0] = emitter[tri[tri >= 0]]
    inner = binary_erosion(on_light, np.ones((3, 3), bool))
    assert inner.sum() >= 5
    row, col = texel_index(out["uv"][inner], scene.maps.atlas_shape)
    ke, radiance = scene.maps.ke[row, col], out["radiance"][inner]
    assert np.all(ke > 0)
    # Per pixel within the ke variation across a pixel footprint; on average within 5 %.
    np.testing.assert_allclose(radiance, ke, rtol=0.2)
    assert radiance.mean() == pytest.approx(ke.mean(), rel=0.05)

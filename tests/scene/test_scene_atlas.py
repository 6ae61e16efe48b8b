"""scene.atlas: xatlas unwrap, texel rasterisation, dilation, atlas.npz."""

import time

import numpy as np
import pytest

from invrender.scene.atlas import AtlasTexels, dilate, rasterize_atlas, texel_index, triangle_areas, unwrap
from invrender.scene.types import Mesh
from invrender.assets.primitives import box, concatenate, cylinder, face_normals


@pytest.fixture(scope="module")
def shapes():
    """A box and a can, side by side, as two groups (two instance ids)."""
    b = box([0, 0, 0], [1.0, 0.5, 0.8], cell=0.25)
    c = cylinder(0.3, 0.6, 24, 2).transformed(np.array([[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]]))
    prim = concatenate(
        [b._replace(part=np.zeros(len(b.faces), np.int32)), c._replace(part=np.ones(len(c.faces), np.int32))]
    )
    return prim


@pytest.fixture(scope="module")
def unwrapped(shapes):
    atlas = unwrap(shapes.positions, shapes.faces, resolution=128, padding=2, groups=shapes.part)
    mesh = Mesh(atlas.positions, atlas.faces, atlas.uvs, instance_ids=shapes.part)
    return atlas, mesh, rasterize_atlas(mesh, atlas.height, atlas.width)


def test_unwrap_keeps_faces_and_corners_aligned(shapes, unwrapped):
    atlas, _, _ = unwrapped
    assert (atlas.height, atlas.width) == (128, 128)
    assert atlas.faces.shape == shapes.faces.shape
    # Face f is still input face f, corner for corner: per-face attributes stay valid.
    np.testing.assert_array_equal(atlas.positions[atlas.faces], shapes.positions.astype(np.float32)[shapes.faces])
    np.testing.assert_array_equal(atlas.positions, shapes.positions.astype(np.float32)[atlas.vertex_map])
    assert atlas.uvs.min() >= 0 and atlas.uvs.max() <= 1


def test_unwrap_groups_never_share_a_vertex(shapes, unwrapped):
    atlas, _, _ = unwrapped
    used_by = [set(np.unique(atlas.faces[shapes.part == g])) for g in (0, 1)]
    assert not used_by[0] & used_by[1]


def test_unwrap_texel_density_mode():
    b = box([0, 0, 0], [1, 1, 1])
    atlas = unwrap(b.positions, b.faces, texels_per_meter=20, padding=1)
    # Six 1 m^2 sides at 20 texels / m: at least 2400 texels, and not absurdly more.
    assert 2400 <= atlas.height * atlas.width <= 4 * 2400
    with pytest.raises(ValueError):
        unwrap(b.positions, b.faces, padding=1)


def test_texels_map_back_to_the_surface(unwrapped):
    """Random surface points, looked up through their UVs (nearest texel), land on texels
    whose stored point is within one texel of them, or on texels dilation fills."""
    atlas, mesh, texels = unwrapped
    rng = np.random.default_rng(1)
    n = 20000
    tri = rng.integers(0, len(mesh.faces), n)
    b = rng.dirichlet([1, 1, 1], n)
    corners = mesh.faces[tri]
    point = np.einsum("nk,nkc->nc", b, atlas.positions[corners].astype(np.float64))
    uv = np.einsum("nk,nkc->nc", b, atlas.uvs[corners].astype(np.float64))
    row, col = texel_index(uv, texels.shape)
    # World size of a texel on each triangle: sqrt(3D area / UV area in texels).
    e = atlas.uvs[mesh.faces][:, 1:].astype(np.float64) - atlas.uvs[mesh.faces][:, :1]
    uv_area = 0.5 * np.abs(e[:, 0, 0] * e[:, 1, 1] - e[:, 0, 1] * e[:, 1, 0]) * texels.shape[0] * texels.shape[1]
    texel_size = np.sqrt(triangle_areas(atlas.positions, mesh.faces) / uv_area)
    covered = texels.mask[row, col]
    assert covered.mean() > 0.9
    dist = np.linalg.norm(texels.position[row, col] - point, axis=1)
    assert np.all(dist[covered] <= np.sqrt(2) * texel_size[tri][covered] + 1e-6)
    _, grown = dilate(np.zeros(texels.shape, np.float32), texels.mask, 2)
    assert grown[row, col].all()


def test_texel_points_normals_and_barycentrics(unwrapped):
    atlas, mesh, texels = unwrapped
    m = texels.mask
    t = texels.triangle[m]
    b = texels.barycentric[m].astype(np.float64)
    assert np.all(b >= -1e-6) and np.allclose(b.sum(1), 1, atol=1e-5)
    # The texel centre's UV is the barycentric mix of the triangle's UVs.
    rows, cols = np.nonzero(m)
    h, w = texels.shape
    centre = np.stack([(cols + 0.5) / w, 1 - (rows + 0.5) / h], 1)
    np.testing.assert_allclose(np.einsum("nk,nkc->nc", b, atlas.uvs[mesh.faces[t]]), centre, atol=1e-5)
    np.testing.assert_allclose(
        texels.position[m], np.einsum("nk,nkc->nc", b, atlas.positions[mesh.faces[t]]), atol=1e-5
    )
    np.testing.assert_allclose(texels.normal[m], face_normals(atlas.positions, mesh.faces)[t], atol=1e-5)


def test_every_triangle_centroid_texel_is_covered_or_dilated(unwrapped):
    atlas, mesh, texels = unwrapped
    row, col = texel_index(atlas.uvs[mesh.faces].mean(axis=1), texels.shape)
    _, grown = dilate(np.zeros(texels.shape), texels.mask, 2)
    assert grown[row, col].all()


def test_dilate_fills_only_empty_texels_from_neighbours():
    values = np.zeros((5, 5, 3), np.float32)
    mask = np.zeros((5, 5), bool)
    values[2, 2], mask[2, 2] = [1, 2, 3], True
    values[0, 0] = 99  # an empty texel's old value must not leak
    out, grown = dilate(values, mask, 1)
    assert grown.sum() == 9 and not grown[0, 0]
    np.testing.assert_array_equal(out[1:4, 1:4].reshape(-1, 3), np.tile([1, 2, 3], (9, 1)))
    out2, grown2 = dilate(values, mask, 2)
    assert grown2.all()
    np.testing.assert_array_equal(out2[0, 0], [1, 2, 3])


def test_atlas_npz_round_trip(unwrapped, tmp_path):
    _, _, texels = unwrapped
    texels.save(tmp_path / "atlas.npz")
    with np.load(tmp_path / "atlas.npz") as data:
        assert set(data.files) == {"triangle", "barycentric", "position", "normal", "mask"}
    loaded = AtlasTexels.load(tmp_path / "atlas.npz")
    for key in ("triangle", "barycentric", "position", "normal", "mask"):
        np.testing.assert_array_equal(getattr(loaded, key), getattr(texels, key))


def test_rasterize_20k_triangles_into_1024_squared_quickly():
    """A UV grid tiling the unit square: every texel centre is covered, in seconds."""
    n = 100  # 2 n^2 = 20 000 triangles
    s = np.linspace(0, 1, n + 1)
    u, v = np.meshgrid(s, s, indexing="ij")
    uvs = np.stack([u.ravel(), v.ravel()], 1).astype(np.float32)
    positions = np.concatenate([uvs, np.zeros((len(uvs), 1), np.float32)], 1)
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    a = (i * (n + 1) + j).ravel()
    faces = np.concatenate([np.stack([a, a + n + 1, a + n + 2], 1), np.stack([a, a + n + 2, a + 1], 1)]).astype(
        np.int32
    )
    start = time.perf_counter()
    texels = rasterize_atlas(Mesh(positions, faces, uvs), 1024, 1024)
    assert time.perf_counter() - start < 10
    assert texels.mask.all()
    # Texel (row, col) centre is at u = (col + .5) / W, v = 1 - (row + .5) / H; here p = (u, v, 0).
    np.testing.assert_allclose(texels.position[0, 0], [0.5 / 1024, 1 - 0.5 / 1024, 0], atol=1e-6)
    np.testing.assert_allclose(texels.position[1023, 5], [5.5 / 1024, 0.5 / 1024, 0], atol=1e-6)

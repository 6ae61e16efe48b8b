"""The DomeLight's lat-long orientation against the UsdLux specification's own statement, the cube
round trip through it, and the mean radiance of mesh lights against an integral done by hand.
The resampling itself (area-weighted, both ways) is tested in tests/scene/test_scene_cubemap.py."""

import numpy as np
import pytest

from invrender.export.lights import latlong_size, mean_radiance
from invrender.scene.cubemap import (
    cube_texel_solid_angles,
    cube_to_direction,
    cube_to_latlong,
    direction_to_cube,
    latlong_to_cube,
)
from invrender.scene.types import Maps, Mesh


def _one_bright_texel(direction, n=8):
    kg = np.zeros((6, n, n, 3), np.float32)
    face, s, t = direction_to_cube(np.asarray(direction, float))
    kg[int(face), min(int(t * n), n - 1), min(int(s * n), n - 1)] = 1.0
    return kg


@pytest.mark.parametrize(
    "direction, where",
    [
        # UsdLux DomeLight / OpenEXR: latitude +pi/2 (top row) is +Y; latitude 0, longitude 0 is +Z
        # (the image centre); longitude pi/2 is +X (a quarter from the left); longitude +-pi is -Z
        # (the left and right edges).
        ((0, 1, 0), (0.0, None)),
        ((0, -1, 0), (1.0, None)),
        ((0, 0, 1), (0.5, 0.5)),
        ((1, 0, 0), (0.5, 0.25)),
        ((-1, 0, 0), (0.5, 0.75)),
        ((0, 0, -1), (0.5, 0.0)),
    ],
)
def test_latlong_orientation_is_the_usdlux_one(direction, where):
    image = cube_to_latlong(_one_bright_texel(direction), *latlong_size(8))
    height, width = image.shape[:2]
    rows, cols = np.nonzero(image[..., 0] > 0)
    row, col = where
    centre_row = rows.mean() / (height - 1)
    assert abs(centre_row - row) < 0.1
    if col is not None:
        centre_col = np.median(cols) / (width - 1) if col else min(cols.min(), width - 1 - cols.max()) / (width - 1)
        assert abs(centre_col - col) < 0.05


def _total(kg):
    n = kg.shape[1]
    return np.einsum("fijc,ij->c", np.asarray(kg, np.float64), cube_texel_solid_angles(n))


@pytest.mark.parametrize("n", [1, 4, 16, 33, 64])
def test_cube_to_latlong_and_back_keeps_the_light(n):
    """Through the export's lat-long size: the total radiance to float32 rounding (the nearest-pixel
    resampling this replaced came back texel-exact here, and lost up to 20 % of a small sun's light
    elsewhere). The export's own round trip is exact through the cube beside the texture (below)."""
    kg = np.random.default_rng(n).random((6, n, n, 3)).astype(np.float32)
    image = cube_to_latlong(kg, *latlong_size(n))
    assert image.shape[:2] == latlong_size(n)[::-1] and image.shape[1] == 2 * image.shape[0]
    back = latlong_to_cube(image, n)
    assert np.allclose(_total(back), _total(kg), rtol=1e-6, atol=0)


def test_the_export_sky_comes_back_exactly_while_its_texture_is_untouched(tmp_path):
    from pxr import Usd

    from invrender.export.lights import author_dome, read_dome, write_sky
    from invrender.scene.images import write_exr

    n = 8
    kg = np.random.default_rng(3).random((6, n, n, 3)).astype(np.float32)
    files = write_sky(kg, tmp_path, "textures")
    stage = Usd.Stage.CreateNew(str(tmp_path / "dome.usda"))
    dome = author_dome(stage, "/dome", files["sky"], n, files["sky_cube"])
    assert np.array_equal(read_dome(dome.GetPrim(), np.eye(4), 16, "test"), kg)
    resampled = read_dome(dome.GetPrim(), np.eye(4), 16, "test", exact=False)  # what the texture says
    assert not np.array_equal(resampled, kg) and np.allclose(_total(resampled), _total(kg), rtol=1e-6, atol=0)
    write_exr(tmp_path / "edited.exr", np.full((8, 16, 3), 2.0, np.float32))  # another tool's sky wins
    dome.CreateTextureFileAttr("./edited.exr")
    assert np.allclose(read_dome(dome.GetPrim(), np.eye(4), 16, "test"), 2.0, rtol=1e-5, atol=0)


def test_a_rotated_dome_turns_the_sky():
    kg = _one_bright_texel((1, 0, 0))
    quarter = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)  # +90 deg about +Y: +X -> -Z
    image = cube_to_latlong(kg, *latlong_size(8))
    turned = latlong_to_cube(image, 8, rotation=quarter)
    target = _one_bright_texel((0, 0, -1))
    brightest = lambda kg: np.unravel_index(np.argmax(kg[..., 0]), kg.shape[:3])
    assert brightest(turned) == brightest(target)
    assert np.allclose(_total(turned), _total(kg), rtol=1e-6, atol=0)
    # as the unturned round trip of the texel already there, up to the lat-long grid not turning onto itself
    assert np.abs(turned - latlong_to_cube(cube_to_latlong(target, *latlong_size(8)), 8)).max() < 0.02


def test_mean_radiance_is_the_area_weighted_mean_of_the_texels_under_the_faces():
    """Two triangles of areas 1 and 3 over texels of radiance 2 and 6: (1 x 2 + 3 x 6) / 4 = 5."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 2], [5, 0, 0], [8, 0, 0], [5, 0, 2]], np.float32)
    uvs = np.array([[0.1, 0.9], [0.2, 0.9], [0.1, 0.8], [0.6, 0.2], [0.7, 0.2], [0.6, 0.1]], np.float32)
    mesh = Mesh(positions, np.array([[0, 1, 2], [3, 4, 5]], np.int32), uvs)
    maps = Maps.uniform(size=(2, 2))
    maps.ke[0, 0], maps.ke[1, 1] = 2.0, 6.0  # texel (row 0, col 0) under the first, (1, 1) under the second
    assert np.allclose(mean_radiance(mesh, maps, np.array([0, 1])), 5.0)
    assert np.allclose(mean_radiance(mesh, maps, np.array([1])), 6.0)


@pytest.mark.parametrize(
    "schema, up, zenith",
    [
        ("DomeLight", "Y", (0, 1, 0)),  # the export's own form
        ("DomeLight_1", "Z", (0, 1, 0)),  # pole on the stage's up axis (poleAxis "scene"), Z up -> our +Y
        ("DomeLight", "Z", (0, 0, -1)),  # DomeLight's pole is the stage's +Y whatever its up axis
    ],
)
def test_imported_dome_puts_its_pole_where_usdlux_says(tmp_path, schema, up, zenith):
    """A sky bright within 29.5 degrees of the lat-long's pole (its top 30 rows) lights the cube
    texels wholly within 29.5 degrees of where the pole must end up in our world fully, those wholly
    beyond not at all, and keeps the cap's light 2 pi (1 - sin 60.5 deg) whole."""
    from pxr import Usd, UsdGeom, UsdLux

    from invrender.export.importer import stage_to_scene
    from invrender.export.lights import read_dome
    from invrender.scene.images import write_exr

    height = 181  # rows 1 degree apart: latitude 90 - i
    image = np.zeros((height, 2 * height, 3), np.float32)
    image[:30] = 1.0  # latitude > 60.5 degrees
    write_exr(tmp_path / "sky.exr", image)
    stage = Usd.Stage.CreateNew(str(tmp_path / "dome.usda"))
    UsdGeom.SetStageUpAxis(stage, up)
    dome = getattr(UsdLux, schema).Define(stage, "/dome")
    dome.CreateTextureFileAttr("./sky.exr")
    n = 16
    kg = read_dome(dome.GetPrim(), stage_to_scene(stage), n, "test")
    corners = np.stack(
        [
            cube_to_direction(
                np.arange(6)[:, None, None],
                (np.arange(n)[None, None, :] + ds) / n,
                (np.arange(n)[None, :, None] + dt) / n,
            )
            for ds in (0, 1)
            for dt in (0, 1)
        ]
    )  # (4, 6, N, N, 3)
    angle = np.degrees(np.arccos(np.clip(corners @ np.asarray(zenith, float), -1, 1)))
    inside, outside = np.all(angle < 29.5, axis=0), np.all(angle > 29.5, axis=0)
    assert inside.sum() > 20 and np.allclose(kg[inside], 1.0, atol=1e-5)
    assert np.all(kg[outside] == 0) and np.any(kg[~inside & ~outside, 0] > 0)
    assert _total(kg)[0] == pytest.approx(2 * np.pi * (1 - np.sin(np.radians(60.5))), rel=1e-6)

"""The DomeLight's lat-long orientation against the UsdLux specification's own statement, the cube
round trip through it, and the mean radiance of mesh lights against an integral done by hand."""

import numpy as np
import pytest

from invrender.export.lights import cube_to_latlong, latlong_size, latlong_to_cube, mean_radiance
from invrender.render.sampling import direction_to_cube
from invrender.scene.types import Maps, Mesh


def _one_bright_texel(direction, n=8):
    kg = np.zeros((6, n, n, 3), np.float32)
    face, s, t = direction_to_cube(np.asarray(direction, float))
    kg[int(face), min(int(t * n), n - 1), min(int(s * n), n - 1)] = 1.0
    return kg


@pytest.mark.parametrize("direction, where", [
    # UsdLux DomeLight / OpenEXR: latitude +pi/2 (top row) is +Y; latitude 0, longitude 0 is +Z
    # (the image centre); longitude pi/2 is +X (a quarter from the left); longitude +-pi is -Z
    # (the left and right edges).
    ((0, 1, 0), (0.0, None)), ((0, -1, 0), (1.0, None)), ((0, 0, 1), (0.5, 0.5)),
    ((1, 0, 0), (0.5, 0.25)), ((-1, 0, 0), (0.5, 0.75)), ((0, 0, -1), (0.5, 0.0)),
])
def test_latlong_orientation_is_the_usdlux_one(direction, where):
    image = cube_to_latlong(_one_bright_texel(direction))
    height, width = image.shape[:2]
    rows, cols = np.nonzero(image[..., 0] > 0)
    row, col = where
    centre_row = rows.mean() / (height - 1)
    assert abs(centre_row - row) < 0.1
    if col is not None:
        centre_col = np.median(cols) / (width - 1) if col else min(cols.min(), width - 1 - cols.max()) / (width - 1)
        assert abs(centre_col - col) < 0.05


@pytest.mark.parametrize("n", [1, 4, 16, 33, 64])
def test_cube_to_latlong_and_back_is_exact(n):
    kg = np.random.default_rng(n).random((6, n, n, 3)).astype(np.float32)
    image = cube_to_latlong(kg)
    assert image.shape[:2] == latlong_size(n)[::-1] and image.shape[1] == 2 * image.shape[0]
    assert np.array_equal(latlong_to_cube(image, n), kg)


def test_a_rotated_dome_turns_the_sky():
    kg = _one_bright_texel((1, 0, 0))
    quarter = np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float)  # +90 deg about +Y: +X -> -Z
    turned = latlong_to_cube(cube_to_latlong(kg), 8, rotation=quarter)
    assert np.array_equal(turned, _one_bright_texel((0, 0, -1)))


def test_mean_radiance_is_the_area_weighted_mean_of_the_texels_under_the_faces():
    """Two triangles of areas 1 and 3 over texels of radiance 2 and 6: (1 x 2 + 3 x 6) / 4 = 5."""
    positions = np.array([[0, 0, 0], [1, 0, 0], [0, 0, 2], [5, 0, 0], [8, 0, 0], [5, 0, 2]], np.float32)
    uvs = np.array([[0.1, 0.9], [0.2, 0.9], [0.1, 0.8], [0.6, 0.2], [0.7, 0.2], [0.6, 0.1]], np.float32)
    mesh = Mesh(positions, np.array([[0, 1, 2], [3, 4, 5]], np.int32), uvs)
    maps = Maps.uniform(size=(2, 2))
    maps.ke[0, 0], maps.ke[1, 1] = 2.0, 6.0  # texel (row 0, col 0) under the first, (1, 1) under the second
    assert np.allclose(mean_radiance(mesh, maps, np.array([0, 1])), 5.0)
    assert np.allclose(mean_radiance(mesh, maps, np.array([1])), 6.0)


@pytest.mark.parametrize("schema, up, zenith", [
    ("DomeLight", "Y", (0, 1, 0)),  # the export's own form
    ("DomeLight_1", "Z", (0, 1, 0)),  # pole on the stage's up axis (poleAxis "scene"), Z up -> our +Y
    ("DomeLight", "Z", (0, 0, -1)),  # DomeLight's pole is the stage's +Y whatever its up axis
])
def test_imported_dome_puts_its_pole_where_usdlux_says(tmp_path, schema, up, zenith):
    """A sky bright within 30 degrees of the lat-long's pole (its top rows) lights exactly the cube
    texels whose centres lie within 30 degrees of where the pole must end up in our world."""
    from pxr import Usd, UsdGeom, UsdLux

    from invrender.export.importer import stage_to_scene
    from invrender.export.lights import read_dome
    from invrender.render.sampling import cube_to_direction
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
    face = np.repeat(np.arange(6), n * n).reshape(6, n, n)
    row, col = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    centres = cube_to_direction(face, np.broadcast_to((col + 0.5) / n, face.shape), np.broadcast_to((row + 0.5) / n, face.shape))
    angle = np.degrees(np.arccos(np.clip(centres @ np.asarray(zenith, float), -1, 1)))
    lit = kg[..., 0] > 0
    assert lit.any() and np.all(angle[lit] < 30.0) and np.all(lit[angle < 28.5])

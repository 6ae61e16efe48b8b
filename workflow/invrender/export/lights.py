"""Lights: the outdoor light kg as a UsdLux.DomeLight, emitting regions as mesh lights.

As MILO exports to other renderers (papers/milo.txt, "Exporting scene to other renderers"),
windows and ceiling lights are split from the geometry (scene/regions.py):

- Windows are openings: their faces go to an invisible mesh, and kg lights the scene from a
  DomeLight through them, as every ray that leaves our scene sees kg.
- Each connected emitting region becomes a mesh light (UsdLux.MeshLightAPI) whose colour x
  intensity is its mean radiance (area-weighted over the texels under it), with
  `light:materialSyncMode = independent`: camera rays see the bound material's emissiveColor,
  texture-exact, and light rays the uniform mean radiance, the two never summed.

The DomeLight's lat-long texture follows the UsdLux specification (the OpenEXR one): pixel
(column j, row i) of a W x H (= 2H x H) image holds the radiance arriving from direction
d = (sin(lon) cos(lat), sin(lat), cos(lon) cos(lat)) with lon = pi - 2 pi j / (W - 1) and
lat = pi / 2 - pi i / (H - 1): +Y up, the image centre looking along +Z, a quarter from the left
along +X, the left and right edges along -Z. It is kg resampled area-weighted (scene/cubemap.py),
so other tools get kg's total light; the exact cube goes beside it (`invrender:cube`), for the
importer while the texture is still the one the export wrote. Mitsuba's `envmap`
(invrender/mitsuba/envmap.py) has the same orientation and rows but places column j at (j + 1/2) / W.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

from ..scene.cubemap import cube_to_latlong, kg_from_stacked, kg_to_stacked, latlong_to_cube
from ..scene.images import read_image, write_exr
from ..scene.regions import face_texels
from ..scene.types import Maps, Mesh, SceneError
from . import schema

__all__ = [
    "latlong_size",
    "write_sky",
    "author_dome",
    "read_dome",
    "mean_radiance",
    "author_mesh_light",
    "light_radiance",
]

LATLONG_PER_TEXEL = 32  # lat-long columns per cube texel row (8 per texel at the horizon)
MIN_LATLONG_WIDTH = 512
SKY_LATLONG, SKY_CUBE = "sky_latlong.exr", "sky_cube.exr"


def latlong_size(n: int) -> tuple[int, int]:
    """(width, height) of the lat-long texture of an N x N cube map: fine enough that a texel's
    edges blur over 1/16 of it at the horizon (a pixel straddling an edge takes the mean)."""
    width = max(MIN_LATLONG_WIDTH, LATLONG_PER_TEXEL * n)
    return width, width // 2


def write_sky(kg: np.ndarray, root, folder: str) -> dict:
    """Write kg as the DomeLight's lat-long texture and as the exact cube (stacked (6 N, N, 3))
    into root/folder; return their asset paths {"sky": ..., "sky_cube": ...}."""
    write_exr(root / folder / SKY_LATLONG, cube_to_latlong(kg, *latlong_size(kg.shape[1])))
    write_exr(root / folder / SKY_CUBE, kg_to_stacked(kg))
    return {"sky": f"./{folder}/{SKY_LATLONG}", "sky_cube": f"./{folder}/{SKY_CUBE}"}


def author_dome(stage: Usd.Stage, path: str, texture: str, n: int, cube: str | None = None) -> UsdLux.DomeLight:
    """The DomeLight of kg: radiance = the lat-long texture (colour 1, intensity 1, exposure 0);
    `cube` the exact cube map beside it, valid while the texture is still `texture`."""
    dome = UsdLux.DomeLight.Define(stage, path)
    dome.CreateTextureFileAttr(texture)
    dome.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
    dome.CreateIntensityAttr(1.0)
    dome.CreateExposureAttr(0.0)
    dome.CreateColorAttr(Gf.Vec3f(1.0, 1.0, 1.0))
    prim = dome.GetPrim()
    prim.CreateAttribute(schema.ROLE, Sdf.ValueTypeNames.Token, custom=True).Set("environment")
    prim.CreateAttribute(schema.CUBE_SIZE, Sdf.ValueTypeNames.Int, custom=True).Set(int(n))
    if cube is not None:
        prim.CreateAttribute(schema.CUBE, Sdf.ValueTypeNames.Asset, custom=True).Set(cube)
        prim.CreateAttribute(schema.CUBE_SOURCE, Sdf.ValueTypeNames.String, custom=True).Set(texture)
    return dome


def _light_scale(light: UsdLux.LightAPI) -> np.ndarray:
    """color x intensity x 2^exposure: what UsdLux multiplies a light's emission by."""
    get = lambda attr, default: default if attr.Get() is None else attr.Get()
    color = np.asarray(get(light.GetColorAttr(), Gf.Vec3f(1, 1, 1)), np.float64)
    return color * float(get(light.GetIntensityAttr(), 1.0)) * 2.0 ** float(get(light.GetExposureAttr(), 0.0))


def read_dome(prim: Usd.Prim, to_scene: np.ndarray, default_n: int, where: str, exact: bool = True) -> np.ndarray:
    """kg (6, N, N, 3) of a DomeLight (or DomeLight_1): its lat-long texture (or white) x colour x
    intensity x 2^exposure, turned by the dome's rotation and pole axis. With `exact`, the export's
    own cube (`invrender:cube`) instead of the texture while the texture and the frame are the
    export's."""
    dome = UsdLux.DomeLight(prim)  # DomeLight_1 has the same texture attributes
    n = prim.GetAttribute(schema.CUBE_SIZE).Get() if prim.HasAttribute(schema.CUBE_SIZE) else None
    n = int(n or default_n)
    scale = _light_scale(UsdLux.LightAPI(prim)).astype(np.float32)
    world = (
        to_scene @ np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()), np.float64).T
    )
    u, _, vt = np.linalg.svd(world[:3, :3])
    rotation = u @ vt @ _pole_rotation(prim)
    turned = not np.allclose(rotation, np.eye(3), rtol=0, atol=1e-12)
    file = dome.GetTextureFileAttr().Get()
    if file is None or not file.path:
        return np.ones((6, n, n, 3), np.float32) * scale
    if not file.resolvedPath:
        raise SceneError(where, f"{prim.GetPath()} inputs:texture:file", f"a texture that exists: {file.path}")
    fmt = dome.GetTextureFormatAttr().Get()
    if fmt not in (None, UsdLux.Tokens.automatic, UsdLux.Tokens.latlong):
        raise SceneError(where, f"{prim.GetPath()} inputs:texture:format", f"latlong, got {fmt}")
    cube = _exact_cube(prim, file.path) if exact and not turned else None
    if cube is not None:
        return cube * scale
    image = read_image(file.resolvedPath)
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise SceneError(
            file.resolvedPath, f"{prim.GetPath()} inputs:texture:file", "a lat-long image of at least 2 x 2 pixels"
        )
    image = np.repeat(image, 3, axis=-1) if image.shape[-1] == 1 else image[..., :3]
    return latlong_to_cube(image, n, rotation if turned else None) * scale


def _exact_cube(prim: Usd.Prim, texture: str) -> np.ndarray | None:
    """The export's cube map, if it names one and the texture is still the one it was made with."""
    if not (prim.HasAttribute(schema.CUBE) and prim.HasAttribute(schema.CUBE_SOURCE)):
        return None
    cube = prim.GetAttribute(schema.CUBE).Get()
    if prim.GetAttribute(schema.CUBE_SOURCE).Get() != texture or cube is None or not cube.resolvedPath:
        return None
    stacked = read_image(cube.resolvedPath)
    if stacked.ndim != 3 or stacked.shape[0] != 6 * stacked.shape[1] or stacked.shape[2] != 3:
        raise SceneError(
            cube.resolvedPath,
            f"{prim.GetPath()} {schema.CUBE}",
            f"a cube map of shape (6 N, N, 3), got {stacked.shape}",
        )
    return kg_from_stacked(stacked.astype(np.float32))


def _pole_rotation(prim: Usd.Prim) -> np.ndarray:
    """DomeLight_1 with its pole on Z (poleAxis "Z", or "scene" on a Z-up stage): the lat-long's +Y
    pole turned onto +Z. DomeLight's pole is +Y whatever the stage's up axis (its specification)."""
    if not prim.IsA(UsdLux.DomeLight_1):
        return np.eye(3)
    pole = UsdLux.DomeLight_1(prim).GetPoleAxisAttr().Get() or UsdLux.Tokens.scene
    if pole == UsdLux.Tokens.scene:
        pole = UsdGeom.GetStageUpAxis(prim.GetStage())
    if pole != "Z":
        return np.eye(3)
    return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # +90 deg about X: +Y -> +Z


def mean_radiance(mesh: Mesh, maps: Maps, face_ids: np.ndarray) -> np.ndarray:
    """Area-weighted mean of ke over some faces (nearest texel, as the renderer looks it up)."""
    faces = mesh.faces[face_ids]
    sample_face, texel = face_texels(mesh.uvs, faces, maps.atlas_shape)
    ke = maps.ke.reshape(-1, 3)[texel].astype(np.float64)
    per_face = np.zeros((len(faces), 3))
    np.add.at(per_face, sample_face, ke)
    per_face /= np.maximum(np.bincount(sample_face, minlength=len(faces)), 1)[:, None]
    p = mesh.positions[faces].astype(np.float64)
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    return per_face.T @ area / max(area.sum(), 1e-300)


def author_mesh_light(prim: Usd.Prim, radiance: np.ndarray) -> None:
    """Make a mesh prim a light of uniform `radiance` for light rays (materialSyncMode independent):
    colour = radiance / its largest channel, intensity = that channel."""
    UsdLux.MeshLightAPI.Apply(prim)
    light = UsdLux.LightAPI(prim)
    peak = float(np.max(radiance))
    color = np.asarray(radiance, np.float64) / peak if peak > 0 else np.zeros(3)
    light.CreateColorAttr(Gf.Vec3f(*color.astype(float)))
    light.CreateIntensityAttr(peak)
    light.CreateExposureAttr(0.0)
    light.CreateNormalizeAttr(False)
    light.CreateMaterialSyncModeAttr(UsdLux.Tokens.independent)


def light_radiance(prim: Usd.Prim) -> np.ndarray | None:
    """A mesh light's uniform radiance (colour x intensity x 2^exposure), None if not a light."""
    if not prim.HasAPI(UsdLux.MeshLightAPI) and not prim.HasAPI(UsdLux.LightAPI):
        return None
    return _light_scale(UsdLux.LightAPI(prim))

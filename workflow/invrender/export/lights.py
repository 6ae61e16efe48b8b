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
along +X, the left and right edges along -Z. Mitsuba's `envmap` (invrender/mitsuba/envmap.py) has
the same orientation and rows but places column j at (j + 1/2) / W, so its image is resampled
here rather than reused. Renderers that filter the texture place pixel centres at (j + 1/2) / W
too; with 8 lat-long columns per cube texel at the horizon that half pixel is 1/16 of a texel.
"""

from __future__ import annotations

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdLux

from ..render.sampling import cube_to_direction, lookup_cube
from ..scene.images import read_image
from ..scene.regions import face_texels
from ..scene.types import Mesh, Maps, SceneError
from . import schema

__all__ = ["latlong_size", "latlong_directions", "cube_to_latlong", "latlong_to_cube", "author_dome",
           "read_dome", "mean_radiance", "author_mesh_light", "light_radiance"]

LATLONG_PER_TEXEL = 32  # lat-long columns per cube texel row (8 per texel at the horizon)
MIN_LATLONG_WIDTH = 512


def latlong_size(n: int) -> tuple[int, int]:
    """(width, height) of the lat-long texture of an N x N cube map: fine enough that each cube
    texel's centre finds a pixel of its own texel (tests/export checks the round trip)."""
    width = max(MIN_LATLONG_WIDTH, LATLONG_PER_TEXEL * n)
    return width, width // 2


def latlong_directions(width: int, height: int) -> np.ndarray:
    """World direction of each pixel of a UsdLux lat-long texture: (height, width, 3)."""
    lon = np.pi - 2.0 * np.pi * np.arange(width) / (width - 1)
    lat = 0.5 * np.pi - np.pi * np.arange(height) / (height - 1)
    lat, lon = np.meshgrid(lat, lon, indexing="ij")
    return np.stack([np.sin(lon) * np.cos(lat), np.sin(lat), np.cos(lon) * np.cos(lat)], -1)


def cube_to_latlong(kg: np.ndarray, width: int | None = None) -> np.ndarray:
    """The kg cube map as a UsdLux lat-long image (H, W, 3): the nearest cube texel per pixel."""
    width, height = (width, width // 2) if width else latlong_size(kg.shape[1])
    return lookup_cube(kg, latlong_directions(width, height)).astype(np.float32)


def latlong_to_cube(image: np.ndarray, n: int, rotation: np.ndarray | None = None) -> np.ndarray:
    """A lat-long image back to a (6, N, N, 3) cube map: each texel takes the pixel nearest its
    centre's direction (in the dome's frame: `rotation` is dome-to-world). With the export's size
    this is exactly the cube the image was made from."""
    height, width = image.shape[:2]
    face = np.repeat(np.arange(6), n * n).reshape(6, n, n)
    row, col = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    d = cube_to_direction(face, np.broadcast_to((col + 0.5) / n, face.shape), np.broadcast_to((row + 0.5) / n, face.shape))
    if rotation is not None:
        d = d @ np.asarray(rotation, np.float64)  # world -> dome frame: R^T d, row vectors
    lat = np.arcsin(np.clip(d[..., 1], -1.0, 1.0))
    lon = np.arctan2(d[..., 0], d[..., 2])
    j = np.clip(np.rint((np.pi - lon) * (width - 1) / (2.0 * np.pi)), 0, width - 1).astype(np.int64)
    i = np.clip(np.rint((0.5 * np.pi - lat) * (height - 1) / np.pi), 0, height - 1).astype(np.int64)
    channels = image[i, j]
    if channels.shape[-1] == 1:
        channels = np.repeat(channels, 3, axis=-1)
    return np.ascontiguousarray(channels[..., :3], np.float32)


def author_dome(stage: Usd.Stage, path: str, texture: str, n: int) -> UsdLux.DomeLight:
    """The DomeLight of kg: radiance = the lat-long texture (colour 1, intensity 1, exposure 0)."""
    dome = UsdLux.DomeLight.Define(stage, path)
    dome.CreateTextureFileAttr(texture)
    dome.CreateTextureFormatAttr(UsdLux.Tokens.latlong)
    dome.CreateIntensityAttr(1.0)
    dome.CreateExposureAttr(0.0)
    dome.CreateColorAttr(Gf.Vec3f(1.0, 1.0, 1.0))
    prim = dome.GetPrim()
    prim.CreateAttribute(schema.ROLE, Sdf.ValueTypeNames.Token, custom=True).Set("environment")
    prim.CreateAttribute(schema.CUBE_SIZE, Sdf.ValueTypeNames.Int, custom=True).Set(int(n))
    return dome


def _light_scale(light: UsdLux.LightAPI) -> np.ndarray:
    """color x intensity x 2^exposure: what UsdLux multiplies a light's emission by."""
    get = lambda attr, default: default if attr.Get() is None else attr.Get()
    color = np.asarray(get(light.GetColorAttr(), Gf.Vec3f(1, 1, 1)), np.float64)
    return color * float(get(light.GetIntensityAttr(), 1.0)) * 2.0 ** float(get(light.GetExposureAttr(), 0.0))


def read_dome(prim: Usd.Prim, to_scene: np.ndarray, default_n: int, where: str) -> np.ndarray:
    """kg (6, N, N, 3) of a DomeLight (or DomeLight_1): its lat-long texture (or white) x colour x
    intensity x 2^exposure, turned by the dome's rotation and pole axis."""
    dome = UsdLux.DomeLight(prim)  # DomeLight_1 has the same texture attributes
    n = prim.GetAttribute(schema.CUBE_SIZE).Get() if prim.HasAttribute(schema.CUBE_SIZE) else None
    n = int(n or default_n)
    scale = _light_scale(UsdLux.LightAPI(prim)).astype(np.float32)
    file = dome.GetTextureFileAttr().Get()
    if file is not None and file.path:
        if not file.resolvedPath:
            raise SceneError(where, f"{prim.GetPath()} inputs:texture:file", f"a texture that exists: {file.path}")
        fmt = dome.GetTextureFormatAttr().Get()
        if fmt not in (None, UsdLux.Tokens.automatic, UsdLux.Tokens.latlong):
            raise SceneError(where, f"{prim.GetPath()} inputs:texture:format", f"latlong, got {fmt}")
        image = read_image(file.resolvedPath)
    else:
        image = np.ones((2, 4, 3), np.float32)
    world = to_scene @ np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()), np.float64).T
    u, _, vt = np.linalg.svd(world[:3, :3])
    rotation = u @ vt @ _pole_rotation(prim)
    return latlong_to_cube(image, n, None if np.array_equal(rotation, np.eye(3)) else rotation) * scale


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

"""COLMAP cameras <-> UsdGeom.Camera, so that a USD camera projects every point to the pixel the
COLMAP camera does.

UsdGeom.Camera measures lens and filmback in tenths of a scene unit (decimetres here, as the stage
is in meters) and looks down its local -Z with +Y up; COLMAP looks down +Z with +Y down. Only
ratios matter to the projection, so the filmback is given a width of 36 mm (0.36) and the rest
follows from the pixel pitch per axis:

    pitch_x = 0.36 / W                       (filmback units per pixel, horizontally)
    focalLength = fx pitch_x                  pitch_y = focalLength / fy
    horizontalAperture = W pitch_x            verticalAperture = H pitch_y
    horizontalApertureOffset = (W/2 - cx) pitch_x
    verticalApertureOffset = (cy - H/2) pitch_y

A point at x_cam (OpenCV axes) then lands on u = fx x/z + cx, v = fy y/z + cy, pixel (0, 0)'s
centre at (0.5, 0.5): the filmback's edges are the image's edges, as in COLMAP. With fx != fy the
pixels are not square: the apertures differ per axis so both focal lengths are reproduced, and the
camera's RenderProduct says so with pixelAspectRatio = pitch_x / pitch_y (a renderer conforming a
W x H image to the filmback then keeps them).

UsdGeom.Camera has no lens distortion: an OPENCV camera is exported as its pinhole part, with a
warning, and its k1, k2, p1, p2 kept in the invrender: attributes (schema.py), so that invrender
reads it back whole while other tools show the undistorted view.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from pxr import Gf, Sdf, Usd, UsdGeom, UsdRender, Vt

from ..scene.types import Camera, SceneError
from . import schema

__all__ = [
    "FILM_WIDTH",
    "Lens",
    "lens_of",
    "camera_from_lens",
    "camera_to_world_gl",
    "author_camera",
    "author_render_product",
    "read_camera",
]

log = logging.getLogger(__name__)

FILM_WIDTH = 0.36  # tenths of a meter: a 36 mm full-frame filmback
CV_TO_GL = np.diag([1.0, -1.0, -1.0])  # OpenCV camera axes -> USD's (x right, y up, z backwards)


@dataclass(frozen=True)
class Lens:
    """The UsdGeom.Camera attributes of a COLMAP camera, as float32 (USD stores them so)."""

    focal: float
    horizontal: float
    vertical: float
    horizontal_offset: float
    vertical_offset: float
    pixel_aspect: float  # pitch_x / pitch_y: 1 for square pixels

    def values(self) -> tuple:
        return (self.focal, self.horizontal, self.vertical, self.horizontal_offset, self.vertical_offset)


def lens_of(camera: Camera) -> Lens:
    """The lens and filmback reproducing a camera's pinhole intrinsics (module docstring)."""
    (fx, fy), (cx, cy) = camera.focal, camera.principal_point
    w, h = float(camera.width), float(camera.height)
    pitch_x = FILM_WIDTH / w
    focal = fx * pitch_x
    pitch_y = focal / fy
    f32 = lambda value: float(np.float32(value))
    return Lens(
        f32(focal),
        f32(w * pitch_x),
        f32(h * pitch_y),
        f32((w / 2 - cx) * pitch_x),
        f32((cy - h / 2) * pitch_y),
        pitch_x / pitch_y,
    )


def camera_from_lens(lens_values, width: int, height: int) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) of a W x H image through a UsdGeom.Camera lens (focal, apertures, offsets)."""
    focal, horizontal, vertical, h_offset, v_offset = (float(v) for v in lens_values)
    pitch_x, pitch_y = horizontal / width, vertical / height
    return focal / pitch_x, focal / pitch_y, width / 2 - h_offset / pitch_x, height / 2 + v_offset / pitch_y


def camera_to_world_gl(camera: Camera) -> np.ndarray:
    """4x4 camera-to-world with USD's camera axes (column vectors): [R^T diag(1, -1, -1), C]."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(camera.R, np.float64).T @ CV_TO_GL
    m[:3, 3] = camera.center
    return m


def _usd_matrix(m: np.ndarray) -> Gf.Matrix4d:
    return Gf.Matrix4d(np.asarray(m, np.float64).T.tolist())  # USD multiplies row vectors


def _numpy_matrix(m: Gf.Matrix4d) -> np.ndarray:
    return np.array(m, np.float64).T


def author_camera(stage: Usd.Stage, path: str, camera: Camera, clipping: tuple[float, float]) -> UsdGeom.Camera:
    """A UsdGeom.Camera reproducing `camera`, with the exact COLMAP camera in invrender: attributes."""
    if np.any(camera.distortion != 0):
        log.warning(
            "camera %s: OPENCV distortion %s cannot be expressed in UsdGeom.Camera: other tools see "
            "its pinhole part (invrender keeps the distortion in %s)",
            camera.name,
            np.round(camera.distortion, 6).tolist(),
            schema.COLMAP_PARAMS,
        )
    lens = lens_of(camera)
    usd = UsdGeom.Camera.Define(stage, path)
    usd.CreateProjectionAttr(UsdGeom.Tokens.perspective)
    usd.CreateFocalLengthAttr(lens.focal)
    usd.CreateHorizontalApertureAttr(lens.horizontal)
    usd.CreateVerticalApertureAttr(lens.vertical)
    usd.CreateHorizontalApertureOffsetAttr(lens.horizontal_offset)
    usd.CreateVerticalApertureOffsetAttr(lens.vertical_offset)
    usd.CreateClippingRangeAttr(Gf.Vec2f(*clipping))
    usd.AddTransformOp().Set(_usd_matrix(camera_to_world_gl(camera)))
    prim = usd.GetPrim()
    prim.CreateAttribute(schema.ROLE, Sdf.ValueTypeNames.Token, custom=True).Set("camera")
    prim.CreateAttribute(schema.COLMAP_NAME, Sdf.ValueTypeNames.String, custom=True).Set(camera.name)
    prim.CreateAttribute(schema.COLMAP_MODEL, Sdf.ValueTypeNames.Token, custom=True).Set(camera.model)
    prim.CreateAttribute(schema.COLMAP_PARAMS, Sdf.ValueTypeNames.DoubleArray, custom=True).Set(
        Vt.DoubleArray([float(p) for p in camera.params])
    )
    prim.CreateAttribute(schema.COLMAP_SIZE, Sdf.ValueTypeNames.Int2, custom=True).Set(
        Gf.Vec2i(int(camera.width), int(camera.height))
    )
    prim.CreateAttribute(schema.COLMAP_R, Sdf.ValueTypeNames.Matrix3d, custom=True).Set(
        Gf.Matrix3d(np.asarray(camera.R, np.float64).tolist())
    )
    prim.CreateAttribute(schema.COLMAP_T, Sdf.ValueTypeNames.Double3, custom=True).Set(
        Gf.Vec3d(*(float(v) for v in camera.t))
    )
    return usd


def author_render_product(stage: Usd.Stage, path: str, camera_path: str, camera: Camera) -> UsdRender.Product:
    """The image a camera makes: its resolution and pixel aspect ratio (non-square when fx != fy)."""
    product = UsdRender.Product.Define(stage, path)
    product.CreateCameraRel().SetTargets([Sdf.Path(camera_path)])
    product.CreateResolutionAttr(Gf.Vec2i(int(camera.width), int(camera.height)))
    product.CreatePixelAspectRatioAttr(float(lens_of(camera).pixel_aspect))
    return product


def _get(prim: Usd.Prim, name: str):
    attr = prim.GetAttribute(name)
    return attr.Get() if attr and attr.HasAuthoredValue() else None


def _stored_camera(prim: Usd.Prim) -> Camera | None:
    """The exact COLMAP camera the export stored, if all of it is there."""
    values = [
        _get(prim, name)
        for name in (
            schema.COLMAP_NAME,
            schema.COLMAP_MODEL,
            schema.COLMAP_PARAMS,
            schema.COLMAP_SIZE,
            schema.COLMAP_R,
            schema.COLMAP_T,
        )
    ]
    if any(v is None for v in values):
        return None
    name, model, params, size, R, t = values
    return Camera(
        name=str(name),
        model=str(model),
        width=int(size[0]),
        height=int(size[1]),
        params=np.array(list(params), np.float64),
        R=np.array(R, np.float64),
        t=np.array(list(t), np.float64),
    )


def _authored_lens(usd: UsdGeom.Camera) -> tuple:
    return tuple(
        float(attr.Get())
        for attr in (
            usd.GetFocalLengthAttr(),
            usd.GetHorizontalApertureAttr(),
            usd.GetVerticalApertureAttr(),
            usd.GetHorizontalApertureOffsetAttr(),
            usd.GetVerticalApertureOffsetAttr(),
        )
    )


def _pose(camera_to_world: np.ndarray, where: str) -> tuple[np.ndarray, np.ndarray]:
    """World-to-camera (R, t), OpenCV axes, from a USD camera-to-world matrix (any scale removed)."""
    u, s, vt = np.linalg.svd(camera_to_world[:3, :3])
    if s.min() <= 0 or np.linalg.det(u @ vt) <= 0:
        raise SceneError(where, "xformOp", "a camera transform that is a rotation (with scale), not a mirror")
    R = (u @ vt @ CV_TO_GL).T
    return R, -R @ camera_to_world[:3, 3]


def read_camera(
    prim: Usd.Prim, to_scene: np.ndarray, resolution: tuple[int, int] | None, where: str, exact: bool = True
) -> Camera:
    """The COLMAP camera of a UsdGeom.Camera prim. `to_scene` maps the stage's world to ours
    (units, up axis); `resolution` is its RenderProduct's, if any. With `exact`, the stored COLMAP
    camera wins wherever the USD lens and pose are still the ones it gives (an edit wins)."""
    usd = UsdGeom.Camera(prim)
    to_world = to_scene @ _numpy_matrix(usd.ComputeLocalToWorldTransform(Usd.TimeCode.Default()))
    stored = _stored_camera(prim) if exact else None
    name = stored.name if stored else str(_get(prim, schema.COLMAP_NAME) or prim.GetName())
    if stored is not None:
        width, height = stored.width, stored.height
    elif resolution is not None:
        width, height = resolution
    else:
        size = _get(prim, schema.COLMAP_SIZE)
        if size is None:
            raise SceneError(
                where, f"camera {prim.GetPath()} resolution", "a RenderProduct naming this camera, with a resolution"
            )
        width, height = int(size[0]), int(size[1])

    lens = _authored_lens(usd)
    if stored is not None and np.array_equal(lens, lens_of(stored).values()):
        model, params = stored.model, stored.params
    else:
        fx, fy, cx, cy = camera_from_lens(lens, width, height)
        distortion = stored.distortion if stored is not None else np.zeros(4)
        model = "OPENCV" if np.any(distortion != 0) else "PINHOLE"
        params = np.array([fx, fy, cx, cy, *distortion] if model == "OPENCV" else [fx, fy, cx, cy], np.float64)
    if stored is not None and np.array_equal(to_world, camera_to_world_gl(stored)):
        R, t = stored.R, stored.t
    else:
        R, t = _pose(to_world, where)
    return Camera(name=name, model=model, width=int(width), height=int(height), params=params, R=R, t=t)

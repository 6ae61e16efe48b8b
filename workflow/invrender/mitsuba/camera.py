"""Our COLMAP cameras as Mitsuba sensors: `perspective` for a PINHOLE camera with fx == fy, else
the `invrender_camera` sensor plugin (any fx, fy, OPENCV distortion). Both integrate each pixel
with a box filter.

Conventions measured on mitsuba 3.9.1 (tests/mitsuba/test_mitsuba_bridge.py checks them):
`perspective` has camera axes x left, y up, z forward (OpenCV's x and y negated), square pixels
only; `principal_point_offset_x/y` shift the film sample position in units of the film size, so
COLMAP's (cx, cy) is offset (0.5 - cx / W, 0.5 - cy / H).
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np

from invrender.scene.types import Camera

UNDISTORT_ITERATIONS = 30


def make_class():
    """The `invrender_camera` sensor for the current variant: COLMAP PINHOLE / SIMPLE_PINHOLE /
    OPENCV, OpenCV axes.

    Properties: fx, fy, cx, cy (pixels), k1, k2, p1, p2, and `to_world` = camera-to-world with
    OpenCV axes (x right, y down, z forward). The film sample position s in [0, 1]^2 is the pixel
    coordinate (s.x W, s.y H), pixel (0, 0)'s centre at (0.5, 0.5) as in COLMAP.
    """

    class ColmapCamera(mi.Sensor):
        def __init__(self, props):
            mi.Sensor.__init__(self, props)
            self.fx, self.fy = float(props["fx"]), float(props["fy"])
            self.cx, self.cy = float(props["cx"]), float(props["cy"])
            self.dist = [float(props.get(k, 0.0)) for k in ("k1", "k2", "p1", "p2")]
            matrix = np.array(props["to_world"].matrix, dtype=np.float32)
            self.cam_to_world = mi.Transform4f(matrix)
            self.size = self.film().size()
            self.m_needs_sample_3 = False

        def _direction(self, position):
            x = (position.x * self.size[0] - self.cx) / self.fx
            y = (position.y * self.size[1] - self.cy) / self.fy
            k1, k2, p1, p2 = self.dist
            if any(self.dist):  # undo the OpenCV distortion by fixed-point iteration
                xd, yd = x, y
                for _ in range(UNDISTORT_ITERATIONS):
                    r2 = x * x + y * y
                    radial = 1.0 + k1 * r2 + k2 * r2 * r2
                    dx = 2.0 * p1 * x * y + p2 * (r2 + 2.0 * x * x)
                    dy = p1 * (r2 + 2.0 * y * y) + 2.0 * p2 * x * y
                    x, y = (xd - dx) / radial, (yd - dy) / radial
            local = dr.normalize(mi.Vector3f(x, y, 1.0))
            return self.cam_to_world @ local

        def sample_ray(self, time, sample1, sample2, sample3, active=True):
            ray = mi.Ray3f(self.cam_to_world.translation(), self._direction(sample2), time, mi.Color0f())
            return ray, mi.Color3f(1.0)

        def sample_ray_differential(self, time, sample1, sample2, sample3, active=True):
            ray, weight = self.sample_ray(time, sample1, sample2, sample3, active)
            ray = mi.RayDifferential3f(ray)
            ray.has_differentials = False  # textures are nearest-texel: no footprint needed
            return ray, weight

        def bbox(self):
            p = self.cam_to_world.translation()
            return mi.ScalarBoundingBox3f(mi.ScalarPoint3f(p), mi.ScalarPoint3f(p))

        def to_string(self):
            return f"ColmapCamera[f=({self.fx}, {self.fy}), c=({self.cx}, {self.cy}), dist={self.dist}]"

    return ColmapCamera


def camera_to_world(camera: Camera) -> np.ndarray:
    """4x4 camera-to-world with OpenCV axes (x right, y down, z forward)."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(camera.R, np.float64).T
    m[:3, 3] = camera.center
    return m


def sensor_dict(camera: Camera, spp: int, seed: int = 0) -> dict:
    """A sensor reproducing the COLMAP camera, with box-filtered film and independent sampler."""
    fx, fy = camera.focal
    cx, cy = camera.principal_point
    w, h = int(camera.width), int(camera.height)
    film = {
        "type": "hdrfilm",
        "width": w,
        "height": h,
        "pixel_format": "rgb",
        "component_format": "float32",
        "rfilter": {"type": "box"},
    }
    sampler = {"type": "independent", "sample_count": int(spp), "seed": int(seed)}
    to_world = camera_to_world(camera)
    if camera.model in ("PINHOLE", "SIMPLE_PINHOLE") and fx == fy:
        # Mitsuba's camera axes are OpenCV's with x and y negated.
        mitsuba_to_world = to_world @ np.diag([-1.0, -1.0, 1.0, 1.0])
        return {
            "type": "perspective",
            "fov": float(np.degrees(2.0 * np.arctan(w / (2.0 * fx)))),
            "fov_axis": "x",
            "principal_point_offset_x": float(0.5 - cx / w),
            "principal_point_offset_y": float(0.5 - cy / h),
            "near_clip": 1e-4,
            "far_clip": 1e7,
            "to_world": mi.ScalarTransform4f(mitsuba_to_world),
            "film": film,
            "sampler": sampler,
        }
    if camera.model not in ("PINHOLE", "SIMPLE_PINHOLE", "OPENCV"):
        raise ValueError(f"camera {camera.name}: model: expected PINHOLE, SIMPLE_PINHOLE or OPENCV, got {camera.model}")
    k1, k2, p1, p2 = (float(v) for v in camera.distortion)
    return {
        "type": "invrender_camera",
        "fx": float(fx),
        "fy": float(fy),
        "cx": float(cx),
        "cy": float(cy),
        "k1": k1,
        "k2": k2,
        "p1": p1,
        "p2": p2,
        "to_world": mi.ScalarTransform4f(to_world),
        "film": film,
        "sampler": sampler,
    }

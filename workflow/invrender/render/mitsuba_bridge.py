"""Express invrender scenes in Mitsuba 3, the reference renderer the tests and benchmarks use.

`scene_to_mitsuba` turns a `Scene` and a `Camera` into a dict for `mi.load_dict`;
`render_mitsuba` loads and renders it. The pieces follow docs/renderer.md:

- Material: the `milo` BSDF plugin below (kd/pi + Beckmann D * Schlick F with the F90 clamp *
  V-cavity G / (4 ci co), two-sided), its kd, ks, ka read from bitmap textures with nearest
  lookup, raw values, clamped at the border.
- Geometry: `scene.mesh` with flat (face) normals, split into at most two Mitsuba meshes: the
  faces under which some texel emits (ke > 0), which carry an `area` emitter whose radiance is
  the ke bitmap, and the rest. Faces whose every texel is a pure window opening (kw = 1,
  kd = ks = ke = 0) are left out, so the environment shows through the hole.
- Environment: an `envmap` resampled from the kg cube map (nearest cube texel at the direction
  of each lat-long pixel, as Mitsuba places that pixel).
- Camera: Mitsuba's `perspective` sensor for a PINHOLE camera with fx == fy, else the
  `invrender_camera` sensor plugin below (any fx, fy, OPENCV distortion undone by a fixed-point
  iteration). Both integrate each pixel with a box filter.
- Integrator: `path` with max_depth = B + 1 and no Russian roulette.

Differences from our model that Mitsuba cannot express (each one a known, documented gap):

- Mitsuba's area emitters are one-sided: a triangle emits only on the side its counter-clockwise
  winding faces (n = (p1 - p0) x (p2 - p0)); ours emit on both sides unless `Mesh.one_sided`
  says otherwise.
- The window term kw * kg(d) on a surface that is kept (kw < 1, or kw = 1 on a face that also
  has kd, ks or ke) is dropped; a warning names how many faces this affects. With
  window_as_hole=False every face is kept and kw is ignored.
- kg goes through Mitsuba's bilinear lat-long interpolation: exact for a uniform kg; at the
  default size (`default_envmap_size`: 32 lat-long pixels per cube texel, at least 1024 x 512) the
  irradiance error is below 0.1 % even for a white-noise kg, but a directly seen cube-texel
  edge is blurred over one lat-long pixel.
- The `depth` AOV is Mitsuba's distance along the ray, not the camera z.

Conventions measured on mitsuba 3.9.1 (tests/render/test_mitsuba_bridge.py checks them):

- `bitmap` textures: row = floor(v H) with row 0 the first row of the array, i.e. v points down.
  Our atlas has v up (row = floor((1 - v) H)), so the mesh is given texcoords (u, 1 - v).
- `envmap`: pixel (row i, column j) of an H x W image holds the radiance arriving from (seen
  looking along) world direction d = (sin phi sin theta, cos theta, -cos phi sin theta),
  theta = pi i / (H - 1), phi = 2 pi (j + 1/2) / W: +Y is up, phi = 0 looks along -Z, phi = pi/2
  along +X; values in between are bilinear.
- `perspective`: camera axes x left, y up, z forward (OpenCV's x and y negated); square pixels
  only; `principal_point_offset_x/y` shift the film sample position in units of the film size,
  so COLMAP's (cx, cy) is offset (0.5 - cx / W, 0.5 - cy / H).
"""

from __future__ import annotations

import glob
import os
import re
import warnings

import numpy as np

from invrender.scene.cubemap import lookup_cube
from invrender.scene.regions import classify_faces, face_texels  # noqa: F401 (the bridge's API too)
from invrender.scene.types import Camera, Scene


def _find_libllvm() -> str | None:
    """The newest system libLLVM >= 16 (drjit's LLVM backend fails on Debian's 14 and 15)."""
    best, best_version = None, 0
    for path in glob.glob("/usr/lib/*/libLLVM*.so*") + glob.glob("/usr/lib/libLLVM*.so*"):
        match = re.search(r"libLLVM[-.]?(?:so\.)?(\d+)", os.path.basename(path))
        if match and int(match.group(1)) >= 16 and int(match.group(1)) > best_version:
            best, best_version = path, int(match.group(1))
    return best


# drjit reads this when its LLVM backend starts, so it has to be set before mitsuba is imported.
if "DRJIT_LIBLLVM_PATH" not in os.environ and (_libllvm := _find_libllvm()):
    os.environ["DRJIT_LIBLLVM_PATH"] = _libllvm

import drjit as dr  # noqa: E402
import mitsuba as mi  # noqa: E402


def llvm_available() -> bool:
    """Whether drjit's LLVM backend has a library it works with (FACTS.md: >= 16 on Debian)."""
    path = os.environ.get("DRJIT_LIBLLVM_PATH")
    return bool(path) and os.path.exists(path)


# llvm_ad_rgb is ~70x faster with the Python plugins (vectorised); scalar_rgb works everywhere.
DEFAULT_VARIANT = "llvm_ad_rgb" if llvm_available() else "scalar_rgb"
# Lat-long width per cube face texel: Mitsuba interpolates the lat-long image bilinearly, and with
# 32 lat-long pixels per cube texel row (at least 1024) the irradiance from a white-noise kg
# (the worst case) moves by < 0.1 % (measured: N = 8..64 -> 0.04-0.07 %).
ENVMAP_WIDTH_PER_TEXEL = 32
MIN_ENVMAP_WIDTH = 1024
KA_MIN = 1e-6  # lowest roughness of the model (render/bsdf.py clamps ka there too)

# ---------------------------------------------------------------------------------------------
# Environment: kg cube map (scene/cubemap.py defines its lookup) -> Mitsuba lat-long envmap
# ---------------------------------------------------------------------------------------------

def envmap_directions(width: int, height: int) -> np.ndarray:
    """World direction of each pixel of a Mitsuba `envmap` of that size: (height, width, 3)."""
    theta = np.pi * np.arange(height) / (height - 1)
    phi = 2.0 * np.pi * (np.arange(width) + 0.5) / width
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    return np.stack([np.sin(phi) * np.sin(theta), np.cos(theta), -np.cos(phi) * np.sin(theta)], -1)


def default_envmap_size(kg: np.ndarray) -> tuple[int, int]:
    """(width, height) of the lat-long image that represents kg to < 0.1 % in irradiance."""
    width = max(MIN_ENVMAP_WIDTH, ENVMAP_WIDTH_PER_TEXEL * kg.shape[1])
    return width, width // 2


def cube_to_latlong(kg: np.ndarray, size=None) -> np.ndarray:
    """Resample the (6, N, N, 3) kg cube map to a Mitsuba lat-long image (H, W, 3), float32:
    each pixel gets the nearest cube texel at its direction. size = (width, height), by
    default `default_envmap_size(kg)`."""
    width, height = size or default_envmap_size(kg)
    return lookup_cube(kg, envmap_directions(width, height)).astype(np.float32)


# ---------------------------------------------------------------------------------------------
# Plugins. Mitsuba classes differ per variant, so each plugin class is made (and registered)
# once per variant, after mi.set_variant.
# ---------------------------------------------------------------------------------------------

_registered: dict[str, dict] = {}


def _make_milo_class():
    """The `milo` BSDF for the current variant (docs/renderer.md, "Material model")."""

    class MiloBSDF(mi.BSDF):
        """f = kd/pi + D(h) F(wi.h) G / (4 ci co); Mitsuba's si.wi is our wo, its wo our wi.

        Sampling: one-sample mixture of cosine-weighted diffuse and Beckmann half-vector
        sampling, chosen in proportion to luminance(kd) and luminance(ks) (= F at normal
        incidence); pdf() returns the mixture density, so eval/pdf/sample are consistent.
        """

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.kd = _texture_property(props, "kd", 0.5, channels=3)
            self.ks = _texture_property(props, "ks", 0.0, channels=3)
            self.ka = _texture_property(props, "ka", 0.1, channels=1)
            sides = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            diffuse = mi.BSDFFlags.DiffuseReflection | sides
            glossy = mi.BSDFFlags.GlossyReflection | sides
            self.m_components = [diffuse, glossy]
            self.m_flags = diffuse | glossy

        # -- the pieces ------------------------------------------------------------------------
        def _params(self, si, active):
            kd = self.kd.eval(si, active)
            ks = self.ks.eval(si, active)
            ka = dr.maximum(self.ka.eval_1(si, active), KA_MIN)
            lum_d, lum_s = mi.luminance(kd), mi.luminance(ks)
            total = lum_d + lum_s
            p_spec = dr.select(total > 0, lum_s / dr.select(total > 0, total, 1.0), 0.0)
            return kd, ks, ka, p_spec

        @staticmethod
        def _beckmann_d(h, ka):
            ch2 = dr.square(h.z)
            tan2 = (dr.square(h.x) + dr.square(h.y)) / ch2  # exact at small angles
            return dr.exp(-tan2 / ka) / (dr.pi * ka * dr.square(ch2))

        @staticmethod
        def _local(si, wo):
            """Our (wo, wi) in the frame flipped to the side of the viewer."""
            flip = si.wi.z < 0
            view = mi.Vector3f(si.wi.x, si.wi.y, dr.abs(si.wi.z))
            light = mi.Vector3f(wo.x, wo.y, dr.select(flip, -wo.z, wo.z))
            return view, light

        def _eval_pdf(self, si, wo, active):
            view, light = self._local(si, wo)
            kd, ks, ka, p_spec = self._params(si, active)
            ci, co = light.z, view.z
            valid = active & (ci > 0) & (co > 0)
            h = dr.normalize(light + view)
            ch = h.z
            wih = dr.dot(light, h)  # = wo.h
            d = self._beckmann_d(h, ka)
            g = dr.minimum(1.0, dr.minimum(2.0 * ch * co / wih, 2.0 * ch * ci / wih))
            f90 = dr.minimum(1.0, 50.0 * ks)
            fresnel = ks + (f90 - ks) * dr.power(dr.maximum(1.0 - wih, 0.0), 5)
            # f ci with the specular part as D G F / (4 co): ci co can underflow at grazing angles
            value = dr.select(valid, kd * (ci * dr.inv_pi) + fresnel * (d * g / (4.0 * co)), 0.0)
            pdf = (1.0 - p_spec) * ci * dr.inv_pi + p_spec * d * ch / (4.0 * wih)
            pdf = dr.select(valid, pdf, 0.0)
            return value, pdf

        # -- the mi.BSDF interface -------------------------------------------------------------
        def eval(self, ctx, si, wo, active=True):
            return self._eval_pdf(si, wo, active)[0]

        def pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(si, wo, active)[1]

        def eval_pdf(self, ctx, si, wo, active=True):
            return self._eval_pdf(si, wo, active)

        def sample(self, ctx, si, sample1, sample2, active=True):
            flip = si.wi.z < 0
            view = mi.Vector3f(si.wi.x, si.wi.y, dr.abs(si.wi.z))
            _, _, ka, p_spec = self._params(si, active)
            use_spec = sample1 < p_spec

            diffuse_dir = mi.warp.square_to_cosine_hemisphere(sample2)
            tan2 = -ka * dr.log(1.0 - sample2.x)
            cos_h = dr.rsqrt(1.0 + tan2)
            sin_h = dr.safe_sqrt(1.0 - dr.square(cos_h))
            sin_phi, cos_phi = dr.sincos(2.0 * dr.pi * sample2.y)
            h = mi.Vector3f(sin_h * cos_phi, sin_h * sin_phi, cos_h)
            spec_dir = 2.0 * dr.dot(view, h) * h - view

            light = dr.select(use_spec, spec_dir, diffuse_dir)
            wo = mi.Vector3f(light.x, light.y, dr.select(flip, -light.z, light.z))

            value, pdf = self._eval_pdf(si, wo, active)
            ok = active & (pdf > 0)
            bs = dr.zeros(mi.BSDFSample3f)
            bs.wo = wo
            bs.pdf = dr.select(ok, pdf, 0.0)
            bs.eta = 1.0
            bs.sampled_component = dr.select(use_spec, mi.UInt32(1), mi.UInt32(0))
            bs.sampled_type = dr.select(
                use_spec, mi.UInt32(+mi.BSDFFlags.GlossyReflection), mi.UInt32(+mi.BSDFFlags.DiffuseReflection)
            )
            weight = dr.select(ok, value / dr.select(ok, pdf, 1.0), 0.0)
            return bs, weight

        def traverse(self, callback):
            callback.put_object("kd", self.kd, mi.ParamFlags.Differentiable)
            callback.put_object("ks", self.ks, mi.ParamFlags.Differentiable)
            callback.put_object("ka", self.ka, mi.ParamFlags.Differentiable)

        def to_string(self):
            return f"MiloBSDF[kd={self.kd}, ks={self.ks}, ka={self.ka}]"

    return MiloBSDF


def _make_camera_class():
    """The `invrender_camera` sensor: COLMAP PINHOLE / SIMPLE_PINHOLE / OPENCV, OpenCV axes.

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
                for _ in range(30):
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


def set_variant(variant: str = DEFAULT_VARIANT) -> None:
    """Select a Mitsuba variant and register this module's plugins for it (idempotent)."""
    if mi.variant() != variant:
        mi.set_variant(variant)
    if variant not in _registered:
        milo, camera = _make_milo_class(), _make_camera_class()
        mi.register_bsdf("milo", lambda props: milo(props))
        mi.register_sensor("invrender_camera", lambda props: camera(props))
        _registered[variant] = {"milo": milo, "invrender_camera": camera}


# ---------------------------------------------------------------------------------------------
# Textures
# ---------------------------------------------------------------------------------------------


def bitmap_texture(image: np.ndarray) -> dict:
    """A Mitsuba `bitmap` texture dict from an (H, W), (H, W, 1) or (H, W, 3) array: nearest
    texel, raw (linear) values, clamped at the border. Looked up at Mitsuba texcoords (u, 1 - v)."""
    image = np.array(image, dtype=np.float32, order="C")  # a writeable, contiguous copy
    if image.ndim == 2:
        image = image[..., None]
    return {"type": "bitmap", "bitmap": mi.Bitmap(image), "raw": True, "filter_type": "nearest", "wrap_mode": "clamp"}


def _texture_property(props, name, default, channels):
    if name not in props:
        return mi.load_dict(bitmap_texture(np.full((1, 1, channels), default, np.float32)))
    value = props[name]
    if isinstance(value, (int, float)) or (isinstance(value, (list, tuple)) and len(value) == channels):
        return mi.load_dict(bitmap_texture(np.broadcast_to(np.asarray(value, np.float32), (1, 1, channels))))
    return value


def milo_bsdf(kd, ks, ka) -> dict:
    """A `milo` BSDF dict; kd, ks are (H, W, 3) maps or RGB values, ka an (H, W) map or a float."""
    as_map = lambda v, c: np.asarray(v, np.float32) if np.ndim(v) >= 2 else np.broadcast_to(np.asarray(v, np.float32), (1, 1, c))
    return {
        "type": "milo",
        "kd": bitmap_texture(as_map(kd, 3)),
        "ks": bitmap_texture(as_map(ks, 3)),
        "ka": bitmap_texture(as_map(ka, 1)),
    }


# ---------------------------------------------------------------------------------------------
# Geometry
# ---------------------------------------------------------------------------------------------


def mesh_object(positions, faces, uvs, name: str, bsdf=None, emitter=None, v_up: bool = False):
    """A Mitsuba mesh with flat normals, unreferenced vertices dropped. Its texcoords are
    (u, 1 - v), so that Mitsuba's bitmaps read our atlas right, or (u, v) with v_up=True (for
    the uv AOV)."""
    used, faces = np.unique(faces.ravel(), return_inverse=True)
    faces = faces.reshape(-1, 3).astype(np.uint32)
    positions = np.asarray(positions, np.float32)[used]
    uv = np.asarray(uvs, np.float32)[used].copy()
    if not v_up:
        uv[:, 1] = 1.0 - uv[:, 1]
    props = mi.Properties()
    props["face_normals"] = True
    if bsdf is not None:
        props["bsdf"] = bsdf if isinstance(bsdf, mi.Object) else mi.load_dict(bsdf)
    if emitter is not None:
        props["emitter"] = emitter if isinstance(emitter, mi.Object) else mi.load_dict(emitter)
    mesh = mi.Mesh(name, len(positions), len(faces), props=props, has_vertex_texcoords=True)
    params = mi.traverse(mesh)
    for key, values in (("vertex_positions", positions), ("faces", faces), ("vertex_texcoords", uv)):
        params[key] = type(params[key])(values.ravel())  # dynamic arrays in every variant
    params.update()
    return mesh


# ---------------------------------------------------------------------------------------------
# Camera
# ---------------------------------------------------------------------------------------------


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


# ---------------------------------------------------------------------------------------------
# Scene
# ---------------------------------------------------------------------------------------------


def scene_to_mitsuba(
    scene: Scene,
    camera: Camera,
    max_bounces: int,
    spp: int,
    variant: str = DEFAULT_VARIANT,
    seed: int = 0,
    window_as_hole: bool = True,
    envmap_size=None,
    integrator: dict | None = None,
    bsdf: dict | None = None,
) -> dict:
    """A dict for `mi.load_dict(..., parallel=False)` that renders `scene` as seen by `camera`.

    max_bounces is our B (Mitsuba max_depth = B + 1). Sets the Mitsuba variant (the mesh and
    texture objects in the dict belong to it). envmap_size = (width, height) of the lat-long
    environment, by default `default_envmap_size(kg)`. `integrator` overrides the path integrator,
    `bsdf` the milo BSDF of the maps (one instance, shared by every mesh).
    """
    set_variant(variant)
    maps, mesh = scene.maps, scene.mesh
    groups = classify_faces(scene, window_as_hole)
    if groups["window_dropped"].any():
        warnings.warn(
            f"{int(groups['window_dropped'].sum())} faces kept as surfaces have texels with kw > 0: "
            "Mitsuba renders them without the window term kw * kg",
            stacklevel=2,
        )

    bsdf = mi.load_dict(bsdf or milo_bsdf(maps.kd, maps.ks, maps.ka))  # one instance shared by all meshes
    out = {
        "type": "scene",
        "integrator": integrator
        or {"type": "path", "max_depth": int(max_bounces) + 1, "rr_depth": int(max_bounces) + 2, "hide_emitters": False},
        "sensor": sensor_dict(camera, spp, seed),
    }
    kept = ~groups["hole"]
    for name, mask, emits in (("surfaces", kept & ~groups["emitter"], False), ("emitters", kept & groups["emitter"], True)):
        if not mask.any():
            continue
        emitter = {"type": "area", "radiance": bitmap_texture(maps.ke)} if emits else None
        out[name] = mesh_object(mesh.positions, mesh.faces[mask], mesh.uvs, name, bsdf=bsdf, emitter=emitter)
    if np.any(maps.kg > 0):
        out["environment"] = {"type": "envmap", "bitmap": mi.Bitmap(cube_to_latlong(maps.kg, envmap_size))}
    return out


def render_mitsuba(
    scene: Scene,
    camera: Camera,
    max_bounces: int,
    spp: int,
    variant: str = DEFAULT_VARIANT,
    seed: int = 0,
    window_as_hole: bool = True,
    envmap_size=None,
) -> np.ndarray:
    """Render with Mitsuba: (H, W, 3) float32 radiance, each pixel box-integrated."""
    scene_dict = scene_to_mitsuba(scene, camera, max_bounces, spp, variant, seed, window_as_hole, envmap_size)
    loaded = mi.load_dict(scene_dict, parallel=False)
    image = mi.render(loaded, spp=int(spp), seed=int(seed))
    return np.array(image, dtype=np.float32)[..., :3]


def render_aovs(
    scene: Scene,
    camera: Camera,
    spp: int = 1,
    variant: str = DEFAULT_VARIANT,
    seed: int = 0,
    window_as_hole: bool = True,
) -> dict[str, np.ndarray]:
    """Per-pixel averages over spp samples of `depth` (distance along the ray, 0 on a miss),
    `uv` (our atlas convention, v up; 0 on a miss) and `hit` (1 on a hit, 0 on a miss).
    Returns {"depth": (H, W), "uv": (H, W, 2), "hit": (H, W)}. With spp = 1 each pixel is one
    sample at a random position inside it."""
    set_variant(variant)
    hole = classify_faces(scene, window_as_hole)["hole"]
    mesh = scene.mesh
    scene_dict = {
        "type": "scene",
        "integrator": {"type": "aov", "aovs": "depth:depth,uv:uv,hit:albedo"},
        "sensor": sensor_dict(camera, spp, seed),
    }
    if (~hole).any():
        white = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
        scene_dict["mesh"] = mesh_object(mesh.positions, mesh.faces[~hole], mesh.uvs, "mesh", bsdf=white, v_up=True)
    loaded = mi.load_dict(scene_dict, parallel=False)
    image = np.array(mi.render(loaded, spp=int(spp), seed=int(seed)), dtype=np.float32)
    return {"depth": image[..., 0], "uv": image[..., 1:3], "hit": image[..., 3]}


# ---------------------------------------------------------------------------------------------
# Gradients: a Lambertian scene in Mitsuba's own BSDF, for its differentiable integrators
# ---------------------------------------------------------------------------------------------

KD_PARAMETER_SUFFIX = "reflectance.data"  # mi.traverse key of diffuse_bsdf's kd bitmap


def diffuse_bsdf(kd) -> dict:
    """Mitsuba's two-sided `diffuse` BSDF reading kd from a bitmap (nearest texel, raw values).

    It is our model with ks = 0 (docs/renderer.md: the F90 clamp makes ks = 0 exactly
    Lambertian). Mitsuba's `prb` differentiates its native BSDFs; the milo plugin above is
    Python, which prb would trace and differentiate too, but more slowly."""
    return {"type": "twosided", "bsdf": {"type": "diffuse", "reflectance": bitmap_texture(kd)}}


def prb_integrator(max_bounces: int) -> dict:
    """Mitsuba's path replay backpropagation for B bounces: max_depth = B + 1, no Russian
    roulette (rr_depth beyond the last bounce), as our integrator."""
    return {"type": "prb", "max_depth": int(max_bounces) + 1, "rr_depth": int(max_bounces) + 2}


def scene_to_mitsuba_diffuse(scene: Scene, camera: Camera, max_bounces: int, spp: int,
                             variant: str = DEFAULT_VARIANT, seed: int = 0, window_as_hole: bool = True,
                             envmap_size=None, integrator: dict | None = None) -> dict:
    """As `scene_to_mitsuba`, for a scene with ks = 0 everywhere, with `diffuse_bsdf(kd)` (one
    instance shared by every mesh, so `mi.traverse` lists its kd once: `kd_parameter`) instead of
    the milo plugin. Emitters are one-sided in Mitsuba (see above): face them into the scene."""
    if np.any(scene.maps.ks > 0):
        raise ValueError("scene_to_mitsuba_diffuse: maps.ks: expected 0 everywhere (a Lambertian scene), "
                         f"got a maximum of {float(scene.maps.ks.max())}")
    return scene_to_mitsuba(scene, camera, max_bounces, spp, variant, seed, window_as_hole, envmap_size, integrator,
                            bsdf=diffuse_bsdf(scene.maps.kd))


def kd_parameter(params) -> str:
    """The key of the kd bitmap of `scene_to_mitsuba_diffuse` in `mi.traverse(scene)`: its data
    is indexed as our atlas (row, column, channel), so its gradient is d/d kd texel by texel."""
    keys = [key for key in params.keys() if key.endswith("bsdf.brdf_0." + KD_PARAMETER_SUFFIX)]
    if len(keys) != 1:
        raise ValueError(f"kd_parameter: expected one diffuse kd bitmap among the scene parameters, got {keys}")
    return keys[0]

"""The Mitsuba 3 bridge (invrender/mitsuba/): each test checks one convention against a number known
independently (a closed form, a projection, a direction, a formula, the kernel), so a wrong sign or
flip fails loudly."""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest

# The bridge first: on import it points drjit at a libLLVM that works (DRJIT_LIBLLVM_PATH).
import invrender.mitsuba as mb  # noqa: I001
from invrender.scene.cubemap import cube_to_direction, direction_to_cube, lookup_cube
from invrender.scene.regions import classify_faces
from invrender.scene.types import Camera, Maps, Mesh, Scene

LLVM = "llvm_ad_rgb"
SCALAR = "scalar_rgb"


def _llvm_works() -> bool:
    if not mb.llvm_available():  # an unsuitable libLLVM aborts the process: do not even try
        return False
    try:
        mb.set_variant(LLVM)
        return float(np.array(mi.Float([1.0, 2.0]) * 2.0).sum()) == 6.0
    except Exception:  # noqa: BLE001 - no usable LLVM: run what scalar_rgb can
        return False


VARIANTS = [LLVM] if _llvm_works() else [SCALAR]  # for renders: llvm when it works
BOTH = [SCALAR] + ([LLVM] if LLVM in VARIANTS else [])  # for cheap checks: every variant we can


# ---------------------------------------------------------------------------------------------
# scene helpers


def look_at_camera(eye, target, up=(0.0, 1.0, 0.0), width=32, height=32, params=None, model="PINHOLE"):
    """A COLMAP camera (OpenCV axes: x right, y down, z forward) at eye looking at target."""
    eye, target, up = (np.asarray(v, np.float64) for v in (eye, target, up))
    z = target - eye
    z /= np.linalg.norm(z)
    x = np.cross(z, up)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    R = np.stack([x, y, z])
    if params is None:
        params = [width, width, width / 2, height / 2]
    return Camera("cam", model, width, height, np.asarray(params, np.float64), R, -R @ eye)


def project(camera: Camera, point) -> np.ndarray:
    """COLMAP pixel coordinates (continuous, pixel (0, 0)'s centre at (0.5, 0.5))."""
    p = camera.R @ np.asarray(point, np.float64) + camera.t
    x, y = p[0] / p[2], p[1] / p[2]
    if camera.model == "OPENCV":
        k1, k2, p1, p2 = camera.distortion
        r2 = x * x + y * y
        radial = 1 + k1 * r2 + k2 * r2 * r2
        x, y = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x), y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    fx, fy = camera.focal
    cx, cy = camera.principal_point
    return np.array([fx * x + cx, fy * y + cy])


def uv_sphere(radius=1.0, rings=24, segments=48) -> Mesh:
    """A convex polyhedron inscribed in a sphere, counter-clockwise seen from outside."""
    theta = np.linspace(0, np.pi, rings + 1)
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    t, p = np.meshgrid(theta, phi, indexing="ij")
    pos = radius * np.stack([np.sin(t) * np.cos(p), np.cos(t), -np.sin(t) * np.sin(p)], -1).reshape(-1, 3)
    uv = np.stack([p / (2 * np.pi), 1 - t / np.pi], -1).reshape(-1, 2)
    idx = np.arange((rings + 1) * (segments + 1)).reshape(rings + 1, segments + 1)
    a, b, c, d = idx[:-1, :-1], idx[1:, :-1], idx[1:, 1:], idx[:-1, 1:]
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    area = np.linalg.norm(np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]]), axis=1)
    faces = faces[area > 1e-12]  # the pole triangles of zero area
    # outward winding: (p1 - p0) x (p2 - p0) points away from the centre
    centre = pos[faces].mean(1)
    normal = np.cross(pos[faces[:, 1]] - pos[faces[:, 0]], pos[faces[:, 2]] - pos[faces[:, 0]])
    flip = np.sum(normal * centre, 1) < 0
    faces[flip] = faces[flip][:, ::-1]
    return Mesh(pos.astype(np.float32), faces.astype(np.int32), uv.astype(np.float32))


def quad(center, right, up, uvs=((0, 0), (1, 0), (1, 1), (0, 1))) -> Mesh:
    """A parallelogram centre +- right +- up, counter-clockwise (front) seen from right x up."""
    c, r, u = (np.asarray(v, np.float64) for v in (center, right, up))
    pos = np.stack([c - r - u, c + r - u, c + r + u, c - r + u]).astype(np.float32)
    return Mesh(pos, np.array([[0, 1, 2], [0, 2, 3]], np.int32), np.asarray(uvs, np.float32))


def sphere_interior_mask(camera: Camera, radius: float, any_corner: bool = False) -> np.ndarray:
    """Pixels all (or any) of whose four corner rays hit a sphere of that radius at the origin."""
    h, w = camera.height, camera.width
    fx, fy = camera.focal
    cx, cy = camera.principal_point
    ys, xs = np.mgrid[0 : h + 1, 0 : w + 1].astype(np.float64)
    d_cam = np.stack([(xs - cx) / fx, (ys - cy) / fy, np.ones_like(xs)], -1)
    d = d_cam @ camera.R  # R^T d_cam for each ray
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    o = camera.center
    b = d @ o
    hit = b * b - (o @ o - radius * radius) > 0
    corners = np.stack([hit[:-1, :-1], hit[1:, :-1], hit[:-1, 1:], hit[1:, 1:]])
    return corners.any(0) if any_corner else corners.all(0)


# ---------------------------------------------------------------------------------------------
# (a) closed form: a convex diffuse object under a uniform environment reflects kd * Lenv


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("bounces", [1, 3])
def test_convex_diffuse_sphere_under_uniform_environment(variant, bounces):
    # A convex object never sees itself: every bounce's first reflected ray escapes to kg = 1,
    # so L = kd * 1 for any B >= 1 (and the background, B = 0 there, is kg = 1).
    scene = Scene(uv_sphere(), Maps.uniform(size=(8, 8), kd=0.5, ks=0.0, ka=0.1, kg=1.0, cube=4))
    camera = look_at_camera([0.0, 1.0, 3.5], [0.0, 0.0, 0.0], width=24, height=24, params=[30, 30, 12, 12])
    image = mb.render_mitsuba(scene, camera, bounces, spp=32, variant=variant, envmap_size=(64, 32))
    inside = sphere_interior_mask(camera, 0.98)
    assert inside.sum() > 100
    assert abs(image[inside].mean() - 0.5) < 0.005
    assert np.allclose(image[~sphere_interior_mask(camera, 1.05, any_corner=True)], 1.0, atol=1e-5)


def test_scalar_variant_renders_the_same_closed_form():
    scene = Scene(uv_sphere(rings=8, segments=16), Maps.uniform(size=(4, 4), kd=0.5, kg=1.0, cube=2))
    camera = look_at_camera([0.0, 0.0, 3.0], [0.0, 0.0, 0.0], width=12, height=12, params=[16, 16, 6, 6])
    image = mb.render_mitsuba(scene, camera, 2, spp=8, variant=SCALAR, envmap_size=(16, 8))
    inside = sphere_interior_mask(camera, 0.9)
    assert abs(image[inside].mean() - 0.5) < 0.01


@pytest.mark.parametrize("variant", VARIANTS)
def test_white_furnace(variant):
    # kd = 1, ks = 0: with the F90 clamp the material is exactly Lambertian and conserves energy.
    scene = Scene(uv_sphere(), Maps.uniform(size=(8, 8), kd=1.0, ks=0.0, ka=0.1, kg=1.0, cube=4))
    camera = look_at_camera([0.0, 0.0, 3.5], [0.0, 0.0, 0.0], width=24, height=24, params=[30, 30, 12, 12])
    image = mb.render_mitsuba(scene, camera, 4, spp=64, variant=variant, envmap_size=(64, 32))
    inside = sphere_interior_mask(camera, 0.98)
    # per-pixel noise (MIS with environment sampling) ~0.03 at 64 spp: the mean's is ~0.0015
    assert np.allclose(image[inside].mean(), 1.0, atol=0.006)


# ---------------------------------------------------------------------------------------------
# (b) the camera: an emitter at a known point shows where COLMAP projects it


CAMERAS = {
    # fx == fy goes through Mitsuba's `perspective` with principal point offsets
    "perspective": ("PINHOLE", [30.0, 30.0, 13.3, 14.1]),
    # fx != fy needs the invrender_camera plugin
    "fx_ne_fy": ("PINHOLE", [35.0, 26.0, 18.4, 10.2]),
    "opencv": ("OPENCV", [30.0, 32.0, 15.5, 13.0, -0.12, 0.03, 0.004, -0.003]),
}


def box_coverage(width, height, lo, hi):
    """Fraction of each pixel covered by the image rectangle [lo, hi] (pixel units)."""
    overlap = lambda a, b, c: np.clip(np.minimum(np.arange(a) + 1, c) - np.maximum(np.arange(a), b), 0, None)
    return overlap(height, lo[1], hi[1])[:, None] * overlap(width, lo[0], hi[0])[None, :]


def weighted_centroid(image):
    ys, xs = np.mgrid[0 : image.shape[0], 0 : image.shape[1]] + 0.5
    return np.array([(image * xs).sum(), (image * ys).sum()]) / image.sum()


@pytest.mark.parametrize("variant", VARIANTS)
@pytest.mark.parametrize("kind", list(CAMERAS))
def test_camera_projects_like_colmap(variant, kind):
    if variant == SCALAR and kind != "perspective":
        pytest.skip("the Python sensor costs a Python call per sample in scalar_rgb (its rays are checked below)")
    model, params = CAMERAS[kind]
    camera = look_at_camera(
        [0.4, 0.3, -2.0], [0.0, 0.1, 1.0], up=(0.1, 1.0, 0.0), width=32, height=24, params=params, model=model
    )
    x_axis, y_axis = camera.R[0], camera.R[1]  # camera right and down in world
    for point in ([0.5, 0.4, 1.5], [-0.3, -0.2, 0.8]):
        point = np.asarray(point)
        depth = (camera.R @ point + camera.t)[2]
        half = 1.3 * depth / params[0]  # about 1.3 pixels
        # fronto-parallel, front side towards the camera: right x up = x_cam x -y_cam = -z_cam
        mesh = quad(point, half * x_axis, -half * y_axis)
        scene = Scene(mesh, Maps.uniform(size=(2, 2), kd=0.0, ks=0.0, ke=1.0, kg=0.0, cube=2))
        image = mb.render_mitsuba(scene, camera, 0, spp=2048, variant=variant)[..., 0]
        # COLMAP's projection of the corners; the box-filtered image is their rectangle's coverage
        corners = np.array([project(camera, p) for p in mesh.positions])
        expected = box_coverage(camera.width, camera.height, corners.min(0), corners.max(0))
        assert expected.sum() > 4.0
        assert np.abs(image - expected).max() < 0.06, (kind, point)
        # the centroid of the coverage moves with the projection: a 0.02-pixel shift fails here
        assert np.allclose(weighted_centroid(image), weighted_centroid(expected), atol=0.02), (kind, point)


@pytest.mark.parametrize("variant", BOTH)
@pytest.mark.parametrize("kind", list(CAMERAS))
def test_camera_ray_through_a_pixel_hits_what_projects_there(variant, kind):
    model, params = CAMERAS[kind]
    camera = look_at_camera(
        [0.4, 0.3, -2.0], [0.0, 0.1, 1.0], up=(0.1, 1.0, 0.0), width=32, height=24, params=params, model=model
    )
    mb.set_variant(variant)
    sensor = mi.load_dict(mb.sensor_dict(camera, spp=1))
    rng = np.random.default_rng(6)
    for point in rng.uniform([-0.6, -0.4, 0.5], [0.6, 0.6, 2.0], (8, 3)):
        px = project(camera, point)
        position = mi.Point2f(float(px[0] / camera.width), float(px[1] / camera.height))
        ray, _ = sensor.sample_ray(0.0, 0.5, position, mi.Point2f(0.5, 0.5))
        origin, direction = np.ravel(np.array(ray.o)), np.ravel(np.array(ray.d))
        assert np.allclose(
            origin + direction * (direction @ (point - origin)), point, atol=2e-5 * np.linalg.norm(point - origin)
        )
        assert np.allclose(np.linalg.norm(direction), 1.0, atol=1e-5)


# ---------------------------------------------------------------------------------------------
# (c) the environment: a one-hot cube texel lands in the direction the cube map says


def opengl_cube_to_direction(face, s, t):
    """The OpenGL cube map table, written out independently of the bridge."""
    sc, tc = 2 * s - 1, 2 * t - 1
    d = {0: (1, -tc, -sc), 1: (-1, -tc, sc), 2: (sc, 1, tc), 3: (sc, -1, -tc), 4: (sc, -tc, 1), 5: (-sc, -tc, -1)}[face]
    d = np.asarray(d, np.float64)
    return d / np.linalg.norm(d)


def test_cube_direction_convention_is_opengl():
    rng = np.random.default_rng(1)
    for face in range(6):
        s, t = rng.uniform(0.05, 0.95, 2)
        assert np.allclose(cube_to_direction(face, s, t), opengl_cube_to_direction(face, s, t))
        d = opengl_cube_to_direction(face, s, t)
        f2, s2, t2 = direction_to_cube(d)
        assert (f2, round(float(s2), 9), round(float(t2), 9)) == (face, round(s, 9), round(t, 9))


@pytest.mark.parametrize("variant", VARIANTS)
def test_one_hot_cube_texels_seen_in_their_direction(variant):
    n, row, col = 4, 1, 2  # asymmetric texel: a flip of s or of t moves it
    empty = Mesh(np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32), np.zeros((0, 2), np.float32))
    for face in range(6):
        maps = Maps.uniform(size=(2, 2), kg=0.0, cube=n)
        maps.kg[face, row, col] = (1.0, 2.0, 3.0)
        d = cube_to_direction(face, (col + 0.5) / n, (row + 0.5) / n)
        up = (0.0, 0.0, 1.0) if abs(d[1]) > 0.9 else (0.0, 1.0, 0.0)
        camera = look_at_camera([0, 0, 0], d, up=up, width=17, height=17, params=[12, 12, 8.5, 8.5])
        image = mb.render_mitsuba(Scene(empty, maps), camera, 0, spp=4, variant=variant)
        assert np.allclose(image[8, 8], (1.0, 2.0, 3.0), atol=1e-4), (face, image[8, 8])
        # neighbouring texel centres (one texel = 1/n of the face, ~20 degrees) are dark
        for dc, dr_ in ((1, 0), (-1, 0), (0, 1), (0, -1)):
            d2 = cube_to_direction(face, (col + dc + 0.5) / n, (row + dr_ + 0.5) / n)
            px = project(camera, camera.center + d2)
            assert np.allclose(image[int(px[1]), int(px[0])], 0.0, atol=1e-4), (face, dc, dr_)


@pytest.mark.parametrize("variant", BOTH)
def test_envmap_pixel_directions_match_mitsuba(variant):
    # Each pixel of a small lat-long image holds a distinct value; Mitsuba, asked for the
    # radiance along the direction the bridge assigns to a pixel, must return exactly it.
    mb.set_variant(variant)
    width, height = 8, 5
    image = np.random.default_rng(7).uniform(1.0, 2.0, (height, width, 3)).astype(np.float32)
    env = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(image)})
    directions = mb.envmap_directions(width, height)
    for i in range(1, height - 1):  # the poles are one direction for a whole row
        for j in range(width):
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = mi.Vector3f(*(-directions[i, j]).astype(np.float32).tolist())
            assert np.allclose(np.ravel(np.array(env.eval(si))), image[i, j], rtol=1e-4), (i, j)


@pytest.mark.skipif(LLVM not in VARIANTS, reason="evaluates the envmap at 2M directions at once")
def test_envmap_resampling_error_below_a_tenth_of_a_percent():
    # Mitsuba interpolates the lat-long image bilinearly, so cube texel edges are blurred over
    # a lat-long pixel; what a surface integrates from it must not move by 0.1 %, even for a
    # white-noise kg (the worst case; measured 0.03-0.07 % here). Fibonacci-sphere quadrature,
    # float64 sums (float32 means over millions of values are off by a percent).
    mb.set_variant(LLVM)
    rng = np.random.default_rng(2)
    kg = rng.uniform(0.0, 5.0, (6, 8, 8, 3)).astype(np.float32)
    assert mb.default_envmap_size(kg) == (1024, 512)
    env = mi.load_dict({"type": "envmap", "bitmap": mi.Bitmap(mb.cube_to_latlong(kg))})
    count = 2_000_000  # quadrature noise ~2e-4 (measured against 8M points and 8192 x 4096)
    i = np.arange(count) + 0.5
    z = 1.0 - 2.0 * i / count
    phi = np.pi * (1.0 + 5.0**0.5) * i
    d = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
    si = dr.zeros(mi.SurfaceInteraction3f, count)
    si.wi = mi.Vector3f(*(-d.astype(np.float32).T))
    seen = _rows(env.eval(si), count).astype(np.float64)
    truth = lookup_cube(kg, d).astype(np.float64)
    for normal in ([0, 1, 0], [1, 0, 0], [0.3, -0.4, 0.866]):  # cosine-weighted irradiance
        cos = np.clip(d @ np.asarray(normal) / np.linalg.norm(normal), 0, None)[:, None]
        assert np.allclose((seen * cos).mean(0), (truth * cos).mean(0), rtol=1e-3)
    assert np.allclose(seen.mean(0), truth.mean(0), rtol=1e-3)


def _rows(values, count) -> np.ndarray:
    """A JIT array of `count` vectors -> (count, channels) numpy."""
    return np.array(values).reshape(-1, count).T


# ---------------------------------------------------------------------------------------------
# (d) the milo BSDF plugin against the docs' formula in float64


def _reference_bsdf_cos(wo, wi, kd, ks, ka):
    """docs/renderer.md with n = +z flipped to the side of wo; f * ci, float64."""
    try:
        from invrender.render.bsdf import milo_bsdf_cos
    except ImportError:
        milo_bsdf_cos = None
    flip = np.where(wo[:, 2] < 0, -1.0, 1.0)[:, None]
    n = np.array([0.0, 0.0, 1.0]) * flip
    if milo_bsdf_cos is not None:
        return milo_bsdf_cos(n, wo, wi, kd, ks, ka)
    ci, co = np.sum(n * wi, 1), np.sum(n * wo, 1)  # pragma: no cover
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    ch, wih = np.sum(n * h, 1), np.sum(wi * h, 1)
    tan2 = np.sum(np.cross(n, h) ** 2, 1) / ch**2
    d = np.exp(-tan2 / ka) / (np.pi * ka * ch**4)
    g = np.minimum(1, np.minimum(2 * ch * co / wih, 2 * ch * ci / wih))
    f = ks + (np.minimum(1, 50 * ks) - ks) * (1 - wih[:, None]) ** 5
    val = kd / np.pi + f * (d * g / (4 * ci * co))[:, None]
    return np.where(((ci > 0) & (co > 0))[:, None], val * ci[:, None], 0.0)


def _bsdf_and_si(variant, kd, ks, ka, wo, plugin="milo"):
    """The plugin and, in a JIT variant, one SurfaceInteraction per viewer direction wo."""
    mb.set_variant(variant)
    bsdf = mi.load_dict(mb.milo_bsdf(kd, ks, ka) | {"type": plugin})
    if variant == SCALAR:
        return bsdf, None
    si = dr.zeros(mi.SurfaceInteraction3f, len(wo))
    si.wi = mi.Vector3f(*(np.asarray(wo, np.float32).T))
    si.uv = mi.Point2f(0.5, 0.5)
    return bsdf, si


def _random_directions(rng, count):
    v = rng.normal(size=(count, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize("variant", BOTH)
@pytest.mark.parametrize(
    "kd,ks,ka",
    [
        ((0.3, 0.5, 0.7), (0.04, 0.5, 0.9), 0.08),
        ((0.8, 0.1, 0.0), (0.0, 0.01, 0.3), 0.6),
        ((0.2, 0.2, 0.2), (0.9, 0.9, 0.9), 0.002),
    ],
)
def test_milo_eval_matches_the_formula(variant, kd, ks, ka):
    rng = np.random.default_rng(3)
    count = 4000 if variant == LLVM else 200
    wo = _random_directions(rng, count)  # viewer, both sides of the surface
    wi = _random_directions(rng, count)
    # plus light directions near the mirror direction, where the lobe of small ka lives
    mirror = wo * np.array([-1.0, -1.0, 1.0]) + 0.05 * rng.normal(size=(count, 3))
    wi[: count // 2] = (mirror / np.linalg.norm(mirror, axis=1, keepdims=True))[: count // 2]
    expected = _reference_bsdf_cos(wo, wi, np.array(kd), np.array(ks), ka)
    bsdf, si = _bsdf_and_si(variant, kd, ks, ka, wo)
    ctx = mi.BSDFContext()
    if variant == LLVM:
        got = _rows(bsdf.eval(ctx, si, mi.Vector3f(*(wi.astype(np.float32).T))), count)
    else:
        got = np.array([_scalar_eval(bsdf, a, b) for a, b in zip(wo, wi)])
    assert np.allclose(got, expected, rtol=2e-4, atol=1e-5)


def _scalar_eval(bsdf, wo, wi):
    si = dr.zeros(mi.SurfaceInteraction3f)
    si.wi = mi.Vector3f(*(float(c) for c in wo))
    si.uv = mi.Point2f(0.5, 0.5)
    return np.array(bsdf.eval(mi.BSDFContext(), si, mi.Vector3f(*(float(c) for c in wi))))


@pytest.mark.parametrize("variant", BOTH)
def test_milo_sample_is_consistent_with_eval_and_pdf(variant):
    rng = np.random.default_rng(4)
    count = 20_000 if variant == LLVM else 60
    wo = _random_directions(rng, count)
    u = rng.uniform(size=(count, 3))
    ctx = mi.BSDFContext()
    if variant == LLVM:
        bsdf, si = _bsdf_and_si(variant, (0.5, 0.3, 0.2), (0.3, 0.3, 0.3), 0.05, wo)
        bs, weight = bsdf.sample(ctx, si, mi.Float(u[:, 0]), mi.Point2f(mi.Float(u[:, 1]), mi.Float(u[:, 2])))
        value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
        rows = [_rows(x, count) for x in (weight, value, pdf, bs.pdf, bs.wo)]
    else:
        mb.set_variant(variant)
        bsdf = mi.load_dict(mb.milo_bsdf((0.5, 0.3, 0.2), (0.3, 0.3, 0.3), 0.05))
        rows = [[] for _ in range(5)]
        for v, (u0, u1, u2) in zip(wo, u):
            si = dr.zeros(mi.SurfaceInteraction3f)
            si.wi = mi.Vector3f(*(float(c) for c in v))
            si.uv = mi.Point2f(0.5, 0.5)
            bs, weight = bsdf.sample(ctx, si, float(u0), mi.Point2f(float(u1), float(u2)))
            value, pdf = bsdf.eval_pdf(ctx, si, bs.wo)
            for row, x in zip(rows, (weight, value, pdf, bs.pdf, bs.wo)):
                row.append(np.ravel(np.array(x)))
        rows = [np.array(r) for r in rows]
    weight, value, pdf, bs_pdf, bs_wo = rows
    ok = bs_pdf[:, 0] > 0
    assert ok.mean() > 0.8
    assert np.all(np.sign(bs_wo[ok, 2]) == np.sign(wo[ok, 2]))  # reflection, on the viewer's side
    assert np.allclose(pdf[ok, 0], bs_pdf[ok, 0], rtol=1e-4)
    assert np.allclose(weight[ok], value[ok] / pdf[ok], rtol=1e-3, atol=1e-6)
    assert np.all(weight[~ok] == 0)


@pytest.mark.skipif(LLVM not in VARIANTS, reason="the chi-square test needs a JIT variant")
@pytest.mark.parametrize("wo", [(0.3, 0.1, 0.95), (0.8, 0.0, -0.3)])
def test_milo_sampling_chi2(wo):
    from mitsuba.chi2 import BSDFAdapter, ChiSquareTest, SphericalDomain

    mb.set_variant(LLVM)
    wo = list(np.asarray(wo) / np.linalg.norm(wo))
    params = mb.milo_bsdf((0.4, 0.4, 0.4), (0.5, 0.5, 0.5), 0.1)
    sample_func, pdf_func = BSDFAdapter("milo", params, wi=mi.Vector3f(*(float(c) for c in wo)))
    chi2 = ChiSquareTest(
        domain=SphericalDomain(), sample_func=sample_func, pdf_func=pdf_func, sample_dim=3, sample_count=400_000, res=61
    )
    assert chi2.run(), chi2.messages


def _eval_pdf_rows(variant, kd, ks, ka, wo, wi, plugin="milo"):
    """The plugin's (f ci (N, 3), pdf (N,)) for viewer directions wo and light directions wi."""
    bsdf, si = _bsdf_and_si(variant, kd, ks, ka, wo, plugin)
    ctx = mi.BSDFContext()
    if variant == LLVM:
        value, pdf = bsdf.eval_pdf(ctx, si, mi.Vector3f(*(np.asarray(wi, np.float32).T)))
        return _rows(value, len(wo)), _rows(pdf, len(wo))[:, 0]
    rows = []
    for a, b in zip(wo, wi):
        si = dr.zeros(mi.SurfaceInteraction3f)
        si.wi = mi.Vector3f(*(float(c) for c in a))
        si.uv = mi.Point2f(0.5, 0.5)
        value, pdf = bsdf.eval_pdf(ctx, si, mi.Vector3f(*(float(c) for c in b)))
        rows.append((np.ravel(np.array(value)), float(pdf)))
    return np.array([r[0] for r in rows]), np.array([r[1] for r in rows])


@pytest.mark.parametrize("variant", BOTH)
def test_ks_zero_is_exactly_lambertian_at_grazing_angles(variant):
    # Without the F90 clamp, ks = 0 would still reflect (1 - wi.h)^5 near the mirror direction.
    rng = np.random.default_rng(5)
    count = 500 if variant == LLVM else 60
    wo = np.tile([np.sin(1.48), 0.0, np.cos(1.48)], (count, 1))  # 85 degrees
    wi = wo * np.array([-1.0, -1.0, 1.0]) + 0.1 * rng.normal(size=(count, 3))
    wi[:, 2] = np.abs(wi[:, 2])
    wi /= np.linalg.norm(wi, axis=1, keepdims=True)
    got, _ = _eval_pdf_rows(variant, (1.0, 1.0, 1.0), (0.0, 0.0, 0.0), 0.1, wo, wi)
    assert np.allclose(got, wi[:, 2:3] / np.pi, rtol=1e-5, atol=1e-7)


def _unit(*v):
    v = np.asarray(v, np.float64)
    return v / np.linalg.norm(v)


# (viewer wo, light wi): the degenerate cases the kernel handles one by one (kernels/bsdf.h), and
# ordinary ones so that the comparison is not all zeros.
DEGENERATE = {
    "n.h = 0, light below": (_unit(0.6, 0.0, 0.8), _unit(0.6, 0.0, -0.8)),
    "n.h = 0, both in the tangent plane": (_unit(1.0, 0.0, 0.0), _unit(0.0, 1.0, 0.0)),
    "wi = -wo: no half vector": (_unit(0.6, 0.0, 0.8), _unit(-0.6, 0.0, -0.8)),
    "light in the tangent plane": (_unit(0.6, 0.0, 0.8), _unit(-1.0, 0.0, 0.0)),
    "viewer in the tangent plane": (_unit(1.0, 0.0, 0.0), _unit(-0.6, 0.0, 0.8)),
    "light grazing, 1e-6 above": (_unit(0.6, 0.0, 0.8), _unit(-1.0, 0.0, 1e-6)),
    "mirror, below the surface": (_unit(0.3, -0.2, -0.9), _unit(-0.3, 0.2, -0.9)),
    "mirror": (_unit(0.3, -0.2, 0.9), _unit(-0.3, 0.2, 0.9)),
    "off the mirror": (_unit(0.5, 0.1, 0.7), _unit(-0.2, 0.3, 0.8)),
}


@pytest.mark.parametrize("variant", BOTH)
def test_milo_at_degenerate_directions_matches_the_kernel(variant):
    # scalar_rgb runs the plugin on Python floats, where 0 / 0 raises: at n.h = 0 it must give
    # what the kernel gives (its specular term is 0 there), in value and in pdf.
    from probe import KernelProbe

    kd, ks, ka = np.array([0.5, 0.4, 0.3]), np.array([0.3, 0.2, 0.1]), 0.3
    wo = np.array([v for v, _ in DEGENERATE.values()])
    wi = np.array([light for _, light in DEGENERATE.values()])
    count = len(wo)
    n = np.array([0.0, 0.0, 1.0]) * np.where(wo[:, 2] < 0, -1.0, 1.0)[:, None]  # the kernel's n is on wo's side
    f, pdf_cos, pdf_spec = KernelProbe().bsdf(
        n, wo, wi, np.tile(kd, (count, 1)), np.tile(ks, (count, 1)), np.full(count, ka)
    )
    luminance = lambda c: c @ np.array([0.212671, 0.715160, 0.072169])  # mi.luminance
    p_spec = luminance(ks) / (luminance(kd) + luminance(ks))
    ci = np.sum(n * wi, 1)
    # the kernel's pdf_cosine is ci / pi without looking at wo; the plugin's pdf is 0 where co = 0
    pdf = np.where(ci > 0, (1 - p_spec) * pdf_cos + p_spec * pdf_spec, 0.0) * (np.abs(wo[:, 2]) > 0)
    got, got_pdf = _eval_pdf_rows(variant, kd, ks, ka, wo, wi)
    assert np.all(np.isfinite(got)) and np.all(np.isfinite(got_pdf))
    assert np.count_nonzero(f.any(1)) == 4, f  # the grazing light and the three ordinary cases
    for k, name in enumerate(DEGENERATE):
        assert np.allclose(got[k], f[k], rtol=1e-4, atol=1e-6), (name, got[k], f[k])
        assert np.isclose(got_pdf[k], pdf[k], rtol=1e-4, atol=1e-6), (name, got_pdf[k], pdf[k])


@pytest.mark.parametrize("variant", BOTH)
def test_usd_preview_lobe_is_ggx_smith_sampled_as_milo(variant):
    # bench export's `usd_preview_lobe`: UsdPreviewSurface's GGX D and separable Smith G at
    # alpha^2 = ka, written out here from Walter et al. 2007 (Eqs. 33, 34); milo's pdf.
    rng = np.random.default_rng(8)
    count = 2000 if variant == LLVM else 80
    kd, ks, ka = np.array([0.3, 0.5, 0.7]), np.array([0.04, 0.5, 0.9]), 0.08
    wo = _random_directions(rng, count)
    mirror = wo * np.array([-1.0, -1.0, 1.0]) + 0.2 * rng.normal(size=(count, 3))
    wi = mirror / np.linalg.norm(mirror, axis=1, keepdims=True)
    n = np.array([0.0, 0.0, 1.0]) * np.where(wo[:, 2] < 0, -1.0, 1.0)[:, None]
    ci, co = np.sum(n * wi, 1), np.sum(n * wo, 1)
    h = (wi + wo) / np.linalg.norm(wi + wo, axis=1, keepdims=True)
    c2, wih = np.sum(n * h, 1) ** 2, np.sum(wi * h, 1)
    d = ka / (np.pi * (c2 * (ka - 1) + 1) ** 2)
    g1 = lambda c: 2 / (1 + np.sqrt(1 + ka * (1 - c**2) / np.maximum(c, 1e-12) ** 2))
    f = ks + (np.minimum(1, 50 * ks) - ks) * np.clip(1 - wih, 0, 1)[:, None] ** 5
    value = kd * ci[:, None] / np.pi + f * (d * g1(ci) * g1(co) / (4 * np.maximum(co, 1e-12)))[:, None]
    expected = np.where(((ci > 0) & (co > 0))[:, None], value, 0.0)
    assert (expected > 0).any(1).mean() > 0.3
    got, pdf = _eval_pdf_rows(variant, kd, ks, ka, wo, wi, plugin="usd_preview_lobe")
    assert np.allclose(got, expected, rtol=2e-4, atol=1e-5)
    assert np.allclose(pdf, _eval_pdf_rows(variant, kd, ks, ka, wo, wi)[1], rtol=1e-6)


# ---------------------------------------------------------------------------------------------
# (e) textures: a 2x2 ke map on a quad shows row 0 at the top (v up: row = floor((1 - v) H))


@pytest.mark.parametrize("variant", VARIANTS)
def test_textured_emitter_quadrants(variant):
    ke = np.zeros((2, 2, 3), np.float32)
    ke[0, 0], ke[0, 1], ke[1, 0], ke[1, 1] = (1, 0, 0), (0, 2, 0), (0, 0, 3), (4, 4, 4)
    maps = Maps.uniform(size=(2, 2), kd=0.0, ks=0.0, kg=0.0, cube=2)
    maps.ke = ke
    # the quad spans x, y in [-1, 1] at z = 0, front towards +z; uv = ((x + 1) / 2, (y + 1) / 2)
    mesh = quad([0, 0, 0], [1, 0, 0], [0, 1, 0])
    camera = look_at_camera([0, 0, 4], [0, 0, 0], width=16, height=16, params=[24, 24, 8, 8])
    image = mb.render_mitsuba(Scene(mesh, maps), camera, 0, spp=4, variant=variant)
    # x, y in [-1, 1] at distance 4 with f = 24: pixels 2..13, the centre at 8
    assert np.allclose(image[3:7, 3:7], ke[0, 0], atol=1e-5)  # top left: row 0, column 0
    assert np.allclose(image[3:7, 9:13], ke[0, 1], atol=1e-5)  # top right
    assert np.allclose(image[9:13, 3:7], ke[1, 0], atol=1e-5)  # bottom left
    assert np.allclose(image[9:13, 9:13], ke[1, 1], atol=1e-5)
    assert np.allclose(image[:, :2], 0.0) and np.allclose(image[:2], 0.0)


# ---------------------------------------------------------------------------------------------
# windows and AOVs


@pytest.mark.parametrize("variant", VARIANTS)
def test_window_faces_are_holes(variant):
    maps = Maps.uniform(size=(4, 4), kd=0.0, ks=0.0, kw=1.0, kg=2.0, cube=2)
    mesh = quad([0, 0, 0], [1, 0, 0], [0, 1, 0])
    camera = look_at_camera([0, 0, 4], [0, 0, 0], width=8, height=8, params=[10, 10, 4, 4])
    seen_through = mb.render_mitsuba(Scene(mesh, maps), camera, 1, spp=4, variant=variant)
    assert np.allclose(seen_through, 2.0, atol=1e-4)
    blocked = mb.render_mitsuba(Scene(mesh, maps), camera, 1, spp=4, variant=variant, window_as_hole=False)
    assert np.allclose(blocked[3:5, 3:5], 0.0)


def test_classify_faces_by_the_texels_under_them():
    # a 4 x 4 atlas: the left half (columns 0-1) is a pure opening, texel (row 3, column 3) emits
    maps = Maps.uniform(size=(4, 4), kd=0.5, ks=0.0, kw=0.0)
    maps.kw[:, :2], maps.kd[:, :2] = 1.0, 0.0
    maps.ke[3, 3] = (2.0, 2.0, 2.0)
    uvs = np.array(
        [
            [0.05, 0.95],
            [0.45, 0.95],
            [0.05, 0.05],  # inside the opening
            [0.30, 0.60],
            [0.70, 0.60],
            [0.30, 0.40],  # straddles it: kept, kw dropped
            [0.80, 0.20],
            [0.95, 0.20],
            [0.95, 0.05],  # over the emitting texel (v up)
            [0.60, 0.90],
            [0.95, 0.90],
            [0.60, 0.70],
        ],
        np.float32,
    )
    mesh = Mesh(
        np.random.default_rng(0).normal(size=(12, 3)).astype(np.float32),
        np.arange(12, dtype=np.int32).reshape(4, 3),
        uvs,
    )
    groups = classify_faces(Scene(mesh, maps))
    assert groups["hole"].tolist() == [True, False, False, False]
    assert groups["window_dropped"].tolist() == [False, True, False, False]
    assert groups["emitter"].tolist() == [False, False, True, False]
    assert not classify_faces(Scene(mesh, maps), window_as_hole=False)["hole"].any()
    camera = look_at_camera([0, 0, 5], [0, 0, 0], width=4, height=4)
    with pytest.warns(UserWarning, match="1 faces kept"):
        mb.scene_to_mitsuba(Scene(mesh, maps), camera, 1, 1, variant=VARIANTS[0])


def test_lambertian_faces_keep_a_texel_of_margin_from_glossy_texels():
    # an 8 x 8 atlas, one glossy texel at (row 2, column 5): v up, so it spans u in [5/8, 6/8),
    # v in (5/8, 6/8]
    maps = Maps.uniform(size=(8, 8), kd=0.5, ks=0.0)
    maps.ks[2, 5] = 0.3
    t = 1 / 8
    uvs = np.array(
        [
            [5.2 * t, 5.2 * t],
            [5.8 * t, 5.2 * t],
            [5.2 * t, 5.8 * t],  # on the glossy texel
            [6.2 * t, 5.2 * t],
            [6.8 * t, 5.2 * t],
            [6.2 * t, 5.8 * t],  # its neighbour: the margin
            [1.2 * t, 1.2 * t],
            [2.8 * t, 1.2 * t],
            [1.2 * t, 2.8 * t],
        ],
        np.float32,
    )  # far away
    mesh = Mesh(
        np.random.default_rng(0).normal(size=(9, 3)).astype(np.float32), np.arange(9, dtype=np.int32).reshape(3, 3), uvs
    )
    assert mb.lambertian_faces(Scene(mesh, maps)).tolist() == [False, False, True]
    maps.ks[:] = 0.0
    assert mb.lambertian_faces(Scene(mesh, maps)).all()


@pytest.mark.parametrize("variant", VARIANTS)
def test_aovs_depth_and_uv(variant):
    mesh = quad([0, 0, 0], [1, 0, 0], [0, 1, 0])
    camera = look_at_camera([0, 0, 4], [0, 0, 0], width=16, height=16, params=[24, 24, 8, 8])
    aov = mb.render_aovs(Scene(mesh, Maps.uniform(size=(2, 2))), camera, spp=1, variant=variant)
    assert np.all(aov["hit"][2:14, 2:14] == 1) and np.all(aov["hit"][:, :2] == 0)
    # pixel (row 5, column 11): a ray through ((11 + a) - 8) / 24, ((5 + b) - 8) / 24, a, b in
    # [0, 1), hits z = 0 at x in [0.5, 0.67), y (up) in [0.33, 0.5): u = (x + 1) / 2, v = (y + 1) / 2
    u, v = aov["uv"][5, 11]
    assert 0.75 <= u <= 0.834 and 0.666 <= v <= 0.75
    assert 4.0 < aov["depth"][5, 11] < 4.2

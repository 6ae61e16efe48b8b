"""A `Scene` and a `Camera` as a Mitsuba scene, and renders of it (radiance, AOVs).

- Material: the `milo` BSDF (milo.py), one instance shared by every mesh, reading the atlas. With
  `lambertian_native=True`, faces with ks = 0 under and around them get Mitsuba's own `diffuse`
  (diffuse.py) instead: the same model there (the F90 clamp makes ks = 0 exactly Lambertian), a
  reference independent of our plugin, and, in `scalar_rgb`, no Python call per sample.
- Geometry: `scene.mesh` with flat normals, split into at most two Mitsuba meshes: the faces
  under which some texel emits (ke > 0), which carry an `area` emitter whose radiance is the ke
  bitmap, and the rest. Faces whose every texel is a pure window opening (kw = 1,
  kd = ks = ke = 0) are left out, so the environment shows through the hole
  (scene/regions.py `classify_faces`).
- Environment: an `envmap` resampled from the kg cube map (envmap.py).
- Camera: camera.py. Integrator: `path` with max_depth = B + 1 and no Russian roulette.

Differences from our model that Mitsuba cannot express (each one a known, documented gap):

- Mitsuba's area emitters are one-sided: a triangle emits only on the side its counter-clockwise
  winding faces (n = (p1 - p0) x (p2 - p0)); ours emit on both sides unless `Mesh.one_sided`
  says otherwise.
- The window term kw * kg(d) on a surface that is kept (kw < 1, or kw = 1 on a face that also
  has kd, ks or ke) is dropped; a warning names how many faces this affects. With
  window_as_hole=False every face is kept and kw is ignored.
- kg goes through Mitsuba's bilinear lat-long interpolation (envmap.py).
- The `depth` AOV is Mitsuba's distance along the ray, not the camera z.
"""

from __future__ import annotations

import warnings

import mitsuba as mi
import numpy as np

from invrender.scene.regions import classify_faces
from invrender.scene.types import Camera, Scene

from .camera import sensor_dict
from .diffuse import diffuse_bsdf
from .envmap import cube_to_latlong
from .integrators import path_integrator
from .mesh import mesh_object
from .milo import milo_bsdf
from .textures import bitmap_texture
from .variant import DEFAULT_VARIANT, set_variant


def lambertian_faces(scene: Scene) -> np.ndarray:
    """(F,) bool: faces under which ks = 0 at every texel of their UV bounding box grown by one
    texel, so that no texel a nearest lookup can reach from the face is glossy (conservative:
    face_texels samples a face at half-texel spacing and may miss a grazed texel)."""
    mesh, ks = scene.mesh, scene.maps.ks
    h, w = ks.shape[:2]
    glossy = np.zeros((h + 1, w + 1), np.int64)  # summed-area table of glossy texels
    glossy[1:, 1:] = np.cumsum(np.cumsum(np.any(ks > 0, -1), 0), 1)
    uv = np.asarray(mesh.uvs, np.float64)[mesh.faces]  # (F, 3, 2)
    col, row = uv[..., 0] * w, (1.0 - uv[..., 1]) * h  # atlas convention: row = floor((1 - v) H)
    c0 = np.clip(np.floor(col.min(1)).astype(np.int64) - 1, 0, w)
    c1 = np.clip(np.floor(col.max(1)).astype(np.int64) + 2, 0, w)
    r0 = np.clip(np.floor(row.min(1)).astype(np.int64) - 1, 0, h)
    r1 = np.clip(np.floor(row.max(1)).astype(np.int64) + 2, 0, h)
    return glossy[r1, c1] - glossy[r0, c1] - glossy[r1, c0] + glossy[r0, c0] == 0


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
    lambertian_native: bool = False,
    roulette_depth: int = 0,
    sky_share: float | None = None,
) -> dict:
    """A dict for `mi.load_dict(..., parallel=False)` that renders `scene` as seen by `camera`.

    max_bounces is our B (Mitsuba max_depth = B + 1). Sets the Mitsuba variant (the mesh and
    texture objects in the dict belong to it). envmap_size = (width, height) of the lat-long
    environment, by default `default_envmap_size(kg)`. `integrator` overrides the path integrator,
    `bsdf` the milo BSDF of the maps (one instance, shared by every mesh). lambertian_native:
    Mitsuba's `diffuse` on `lambertian_faces` (see above). roulette_depth: ours (0: none).
    sky_share: the share of emitter samples that go to the envmap (its `sampling_weight` against
    the area emitters' 1 each), as our light split w_env / (w_env + w_emit); None: Mitsuba's own
    even choice among its emitters.
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
        "integrator": integrator or path_integrator(max_bounces, roulette_depth),
        "sensor": sensor_dict(camera, spp, seed),
    }
    kept = ~groups["hole"]
    kinds = (("surfaces", kept & ~groups["emitter"], False), ("emitters", kept & groups["emitter"], True))
    materials = [("", np.ones(len(mesh.faces), bool), bsdf)]
    if lambertian_native:
        lambertian = lambertian_faces(scene)
        materials = [("", ~lambertian, bsdf), ("_lambertian", lambertian, mi.load_dict(diffuse_bsdf(maps.kd)))]
    for suffix, faces, material in materials:
        for name, mask, emits in kinds:
            if not (mask & faces).any():
                continue
            emitter = {"type": "area", "radiance": bitmap_texture(maps.ke)} if emits else None
            out[name + suffix] = mesh_object(
                mesh.positions, mesh.faces[mask & faces], mesh.uvs, name + suffix, bsdf=material, emitter=emitter
            )
    if np.any(maps.kg > 0):
        out["environment"] = {"type": "envmap", "bitmap": mi.Bitmap(cube_to_latlong(maps.kg, envmap_size))}
        areas = sum(1 for key in out if key.startswith("emitters"))
        if sky_share is not None and areas and 0 < sky_share < 1:
            out["environment"]["sampling_weight"] = float(sky_share / (1 - sky_share) * areas)
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
    bsdf: dict | None = None,
    lambertian_native: bool = False,
) -> np.ndarray:
    """Render with Mitsuba: (H, W, 3) float32 radiance, each pixel box-integrated. `bsdf` and
    `lambertian_native` as in `scene_to_mitsuba`."""
    scene_dict = scene_to_mitsuba(
        scene,
        camera,
        max_bounces,
        spp,
        variant,
        seed,
        window_as_hole,
        envmap_size,
        bsdf=bsdf,
        lambertian_native=lambertian_native,
    )
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


def scene_to_mitsuba_diffuse(
    scene: Scene,
    camera: Camera,
    max_bounces: int,
    spp: int,
    variant: str = DEFAULT_VARIANT,
    seed: int = 0,
    window_as_hole: bool = True,
    envmap_size=None,
    integrator: dict | None = None,
) -> dict:
    """As `scene_to_mitsuba`, for a scene with ks = 0 everywhere, with `diffuse_bsdf(kd)` (one
    instance shared by every mesh, so `mi.traverse` lists its kd once: `kd_parameter`) instead of
    the milo plugin. Emitters are one-sided in Mitsuba (see above): face them into the scene."""
    if np.any(scene.maps.ks > 0):
        raise ValueError(
            "scene_to_mitsuba_diffuse: maps.ks: expected 0 everywhere (a Lambertian scene), "
            f"got a maximum of {float(scene.maps.ks.max())}"
        )
    return scene_to_mitsuba(
        scene,
        camera,
        max_bounces,
        spp,
        variant,
        seed,
        window_as_hole,
        envmap_size,
        integrator,
        bsdf=diffuse_bsdf(scene.maps.kd),
    )

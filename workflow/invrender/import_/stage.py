"""The `import` stage: a folder of textured OBJ files (+ MTL, images), a lat-long environment map
and cameras -> a scene directory (format v2) that every later stage reads.

Each (OBJ file, ``usemtl`` material) becomes one object with the identity transform. Its
material set is the material's textures used as they are when the object's UVs stay in [0, 1]
(objects that share a material then share its texels, as in the file), or, when UVs tile
outside [0, 1], an atlas of its own: the object is unwrapped by xatlas and the tiled textures
are baked into it. Materials follow scene/mtl.py; an object whose material is named by
``windows`` is an opening (kw = 1, no reflection) through which the environment is seen. The
environment map is converted to the cube map kg with area-weighted filtering
(scene/cubemap.py), which keeps its total radiance.
"""

from __future__ import annotations

import logging
from pathlib import Path

import cv2
import numpy as np

from ..scene.atlas import bake, rasterize_atlas, triangle_areas, unwrap
from ..scene.atomic import check_output
from ..scene.cameras import read_cameras
from ..scene.cubemap import latlong_to_cube
from ..scene.format import write_scene
from ..scene.images import read_image
from ..scene.mesh_io import read_obj_parts
from ..scene.mtl import MtlMaterial, read_mtl
from ..scene.packing import pack_scene
from ..scene.types import Atlas, Mesh, SceneError, SceneObject, require_positive

log = logging.getLogger(__name__)

CONSTANT_ATLAS = (1, 1)  # a material without textures is one texel
# A baked atlas's texels per texture texel (along each axis): the atlas grid is not aligned with
# the texture's, so nearest-texel baking moves the texture's edges by up to half an atlas texel;
# at 4 that is an eighth of a texture texel (measured against Mitsuba reading the texture itself,
# tests/import_/test_import_mitsuba.py).
OVERSAMPLE = 4.0


def run(
    source,
    out_dir,
    cameras=None,
    environment=None,
    cube_size: int = 64,
    emission_sides: str = "one",
    windows: tuple[str, ...] = (),
    max_atlas: int = 2048,
) -> dict:
    """Import ``source`` (a folder of .obj files, or one .obj) into the scene directory ``out_dir``.

    ``cameras``: a COLMAP model or transforms.json (default: ``source/sparse`` or
    ``source/transforms.json`` when present; a scene may have none). ``environment``: a lat-long
    image (EXR or PNG), +Y up, as docs/export.md's DomeLight convention; none: black.
    ``emission_sides``: "one" (the default here: authored models have consistent winding, and
    Mitsuba, Cycles and USD mesh lights emit from the front only) or "two". Returns a summary.
    """
    check_output(out_dir, "scene")  # before the work, not after it
    cube_size = require_positive("import --cube-size", "texels", cube_size)
    max_atlas = require_positive("import --max-atlas", "texels", max_atlas)
    source = Path(source)
    obj_files = sorted(source.glob("*.obj")) if source.is_dir() else [source]
    if not obj_files:
        raise SceneError(source, "(folder)", "at least one .obj file")
    objects, materials = [], {}
    for obj_path in obj_files:
        for obj, atlas_key, atlas in import_obj(obj_path, emission_sides, set(windows), max_atlas):
            objects.append(obj)
            materials.setdefault(atlas_key, atlas)
    kg = environment_cube(environment, cube_size)
    scene = pack_scene(objects, materials, kg, find_cameras(source, cameras))
    write_scene(Path(out_dir), scene)
    summary = {
        "objects": len(objects),
        "material_sets": len(materials),
        "faces": int(scene.mesh.triangle_count),
        "atlas": list(scene.maps.atlas_shape),
        "cameras": len(scene.cameras),
        "cube_size": int(kg.shape[1]),
    }
    log.info("imported %s -> %s: %s", source, out_dir, summary)
    return summary


def find_cameras(source: Path, cameras) -> list:
    if cameras is not None:
        return read_cameras(cameras)
    folder = source if source.is_dir() else source.parent
    for candidate in (folder / "sparse" / "0", folder / "sparse", folder / "transforms.json"):
        if candidate.exists():
            return read_cameras(candidate)
    return []


def environment_cube(environment, cube_size: int) -> np.ndarray:
    if environment is None:
        return np.zeros((6, 1, 1, 3), np.float32)
    image = read_image(environment)
    rgb = image[..., :3] if image.shape[2] >= 3 else np.repeat(image, 3, axis=2)
    return latlong_to_cube(rgb, cube_size).astype(np.float32)


def import_obj(obj_path: Path, emission_sides: str, windows: set, max_atlas: int):
    """(SceneObject, material-set key, Atlas) for each material part of one OBJ file."""
    parts, mtllibs = read_obj_parts(obj_path)
    library = {}
    for name in mtllibs:
        library |= read_mtl(obj_path.parent / name)
    for material_name, mesh in parts:
        if material_name and material_name not in library:
            raise SceneError(obj_path, f"usemtl {material_name}", f"a material of its mtllib ({', '.join(mtllibs)})")
        material = library.get(
            material_name, MtlMaterial(material_name or "default", {"kd": np.full(3, 0.8, np.float32)})
        )
        object_name = obj_path.stem if len(parts) == 1 else f"{obj_path.stem}.{material_name or 'default'}"
        mesh, key, atlas = material_set(object_name, mesh, material, material.name in windows, max_atlas)
        yield SceneObject(object_name, mesh, key, emission_sides=emission_sides), key, atlas


def material_set(object_name: str, mesh: Mesh, material: MtlMaterial, window: bool, max_atlas: int):
    """(the object's mesh with UVs in its set's atlas, the set's key, the set's Atlas)."""
    if window:  # an opening: nothing reflects, the sky comes through
        atlas = Atlas.uniform(CONSTANT_ATLAS, kd=0.0, ks=0.0, ka=1.0, ke=0.0, kw=1.0)
        return with_uvs(mesh), f"{material.name}", atlas
    if not material.maps:
        return with_uvs(mesh), material.name, constant_atlas(material)
    if mesh.uvs is None:
        raise SceneError(
            material.maps[next(iter(material.maps))],
            f"{object_name} vt",
            "texture coordinates on an object whose material has textures",
        )
    if np.all((mesh.uvs >= 0) & (mesh.uvs <= 1)):
        return mesh, material.name, texture_atlas(material, max_atlas)
    return baked_atlas(object_name, mesh, material, max_atlas)


def with_uvs(mesh: Mesh) -> Mesh:
    """A constant material reads one texel: every UV at its centre."""
    return Mesh(mesh.positions, mesh.faces, np.full((len(mesh.positions), 2), 0.5, np.float32), mesh.instance_ids)


def constant_atlas(material: MtlMaterial) -> Atlas:
    return Atlas.uniform(
        CONSTANT_ATLAS,
        kd=material.constant("kd"),
        ks=material.constant("ks"),
        ka=material.constant("ka"),
        ke=material.constant("ke"),
        kw=0.0,
    )


def texture_atlas(material: MtlMaterial, max_atlas: int) -> Atlas:
    """The textures themselves as the atlas, at the size of the largest (capped at max_atlas):
    the others are resampled to it by area averaging, constants broadcast."""
    images = {key: material.image(key) for key in ("kd", "ks", "ke")}
    sizes = [image.shape[:2] for image in images.values() if image is not None]
    h, w = max(sizes, key=lambda s: s[0] * s[1])
    scale = min(1.0, max_atlas / max(h, w))
    h, w = max(1, round(h * scale)), max(1, round(w * scale))
    maps = {}
    for key, image in images.items():
        if image is None:
            maps[key] = np.broadcast_to(material.constant(key), (h, w, 3)).astype(np.float32)
        else:
            maps[key] = image if image.shape[:2] == (h, w) else cv2.resize(image, (w, h), interpolation=cv2.INTER_AREA)
    ka = np.full((h, w), material.constant("ka"), np.float32)
    return Atlas(
        kd=clip_albedo(maps["kd"]), ks=clip_albedo(maps["ks"]), ka=ka, ke=maps["ke"], kw=np.zeros((h, w), np.float32)
    )


def clip_albedo(rgb: np.ndarray) -> np.ndarray:
    """Albedos live in [0, 1] (MILO Eq. 3); a texture times a colour can overshoot."""
    return np.clip(rgb, 0.0, 1.0).astype(np.float32)


def baked_atlas(object_name: str, mesh: Mesh, material: MtlMaterial, max_atlas: int):
    """UVs that tile: unwrap the object into an atlas of its own and bake the tiled textures
    into it (each texel reads the texture at its point's wrapped UV, nearest texel)."""
    charts = unwrap(mesh.positions, mesh.faces, texels_per_meter=texture_density(mesh, material))
    if max(charts.height, charts.width) > max_atlas:
        charts = unwrap(mesh.positions, mesh.faces, resolution=max_atlas)
    unwrapped = Mesh(charts.positions, charts.faces, charts.uvs, None)
    texels = rasterize_atlas(unwrapped, charts.height, charts.width)
    source_uvs = np.asarray(mesh.uvs, np.float64)[np.asarray(mesh.faces)]  # xatlas keeps face order

    def sample(key):
        image = material.image(key)

        def shade(triangles, positions, normals):
            if image is None:
                return np.broadcast_to(material.constant(key), (len(triangles), 3))
            bary = texels.barycentric[texels.mask]
            uv = np.einsum("nk,nkc->nc", bary, source_uvs[triangles]) % 1.0
            h, w = image.shape[:2]
            rows = np.clip(((1.0 - uv[:, 1]) * h).astype(np.int64), 0, h - 1)
            cols = np.clip((uv[:, 0] * w).astype(np.int64), 0, w - 1)
            return image[rows, cols]

        return bake(texels, shade, 3, dilation=2)

    h, w = texels.shape
    atlas = Atlas(
        kd=clip_albedo(sample("kd")),
        ks=clip_albedo(sample("ks")),
        ka=np.full((h, w), material.constant("ka"), np.float32),
        ke=sample("ke"),
        kw=np.zeros((h, w), np.float32),
    )
    log.info("%s: UVs tile outside [0, 1]: baked %s into an atlas of %d x %d", object_name, material.name, w, h)
    return unwrapped, f"{object_name}-{material.name}", atlas


def texture_density(mesh: Mesh, material: MtlMaterial) -> float:
    """Texels per meter at which the baked atlas keeps the tiled texture's detail: the
    texture's own density on the surface (its texels over the UV area, per 3D area), OVERSAMPLE
    times over."""
    texels = max(image.shape[0] * image.shape[1] for image in map(material.image, material.maps))
    corners_uv = np.asarray(mesh.uvs, np.float64)[mesh.faces]
    e1, e2 = corners_uv[:, 1] - corners_uv[:, 0], corners_uv[:, 2] - corners_uv[:, 0]
    uv_area = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    return OVERSAMPLE * float(np.sqrt(texels * uv_area / triangle_areas(mesh.positions, mesh.faces).sum()))

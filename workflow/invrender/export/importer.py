"""`invrender import-usd`: a USD stage of the export's form, perhaps edited in another tool, back
into a scene directory.

- Meshes: every visible UsdGeom.Mesh, instances included, in world coordinates (meters, +Y up:
  other units and a +Z up axis are converted). The export's invisible window openings come back
  as the windows they were. Faces and vertices are put back in the scene's order where the
  invrender: numbers are still valid; new or re-shaped prims come after.
- Maps: one atlas, as the renderer has one. The material bound to most faces gives it; a prim
  whose material says something else for a map (another texture, a constant: an edit) has that
  map re-baked into the texels under its faces. A mesh light whose colour x intensity no longer
  is the mean radiance of its emission has its ke scaled to match.
- kg: the export's exact cube map while the DomeLight's texture is the export's, else the
  lat-long texture resampled to the cube (area-weighted: scene/cubemap.py).
- Cameras: every UsdGeom.Camera (cameras.py), the exact COLMAP camera where it is untouched.
- Duplicates: instances become poses again (scene.json metadata `poses`, DESIGN.md form), so the
  next export instances them again; the names of prims become instance names.

With `exact=False` every invrender: attribute about appearance is ignored: the scene is what a
tool that knows only the standard schemas sees (ka from roughness^4, no kw, the mesh lights'
uniform radiance as ke, PINHOLE cameras from the USD lens, window openings left open). Comparing
its renders with the original's measures what the export loses for those tools.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pxr import Tf, Usd, UsdGeom, UsdLux, UsdRender, UsdShade

from ..scene.format import write_scene
from ..scene.regions import face_texels
from ..scene.types import Maps, Mesh, Scene, SceneError
from . import schema
from .cameras import read_camera
from .geometry import MeshPiece, read_mesh
from .lights import light_radiance, mean_radiance, read_dome
from .materials import MaterialSources, evaluate_maps, read_material, texture_shape

__all__ = ["import_usd", "read_stage", "stage_to_scene", "assemble"]

log = logging.getLogger(__name__)

MAP_NAMES = ("kd", "ks", "ka", "ke", "kw")
DEFAULT_ATLAS = (64, 64)
DEFAULT_CUBE = 16


@dataclass
class ImportedPiece:
    prim: str
    piece: MeshPiece  # positions in the scene's world frame
    material: str  # path of the bound material ("" for none)
    light: np.ndarray | None = None  # a mesh light's uniform radiance
    role: str = "surface"
    instance_pose: np.ndarray | None = None  # instanced: object-to-world of the instance


@dataclass
class StageContents:
    pieces: list[ImportedPiece] = field(default_factory=list)
    materials: dict[str, MaterialSources] = field(default_factory=dict)
    kg: np.ndarray | None = None
    cameras: list = field(default_factory=list)


def stage_to_scene(stage: Usd.Stage) -> np.ndarray:
    """4x4 from the stage's world to ours (meters, +Y up): metersPerUnit scale, +Z up turned to +Y."""
    m = np.eye(4)
    m[:3, :3] *= UsdGeom.GetStageMetersPerUnit(stage)
    if UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z:
        m = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], np.float64) @ m
    return m


def _world(prim: Usd.Prim, to_scene: np.ndarray) -> np.ndarray:
    local_to_world = np.array(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(Usd.TimeCode.Default()), np.float64)
    return to_scene @ local_to_world.T  # USD matrices act on row vectors


def _transform(positions: np.ndarray, m: np.ndarray) -> np.ndarray:
    if np.array_equal(m, np.eye(4)):
        return positions  # untouched float32 positions stay bit for bit
    return (positions.astype(np.float64) @ m[:3, :3].T + m[:3, 3]).astype(np.float32)


def _instance_root(prim: Usd.Prim) -> Usd.Prim | None:
    while prim and prim.IsInstanceProxy():
        prim = prim.GetParent()
    return prim if prim and prim.IsInstance() else None


def _role(prim: Usd.Prim | None) -> str | None:
    attr = prim.GetAttribute(schema.ROLE) if prim else None
    return str(attr.Get()) if attr and attr.HasAuthoredValue() else None


def read_stage(stage: Usd.Stage, where: str, exact: bool = True) -> StageContents:
    """Everything the scene needs from a stage (module docstring)."""
    to_scene = stage_to_scene(stage)
    contents = StageContents()
    resolutions = {}
    for prim in stage.Traverse():
        if prim.IsA(UsdRender.Product):
            product = UsdRender.Product(prim)
            resolution = product.GetResolutionAttr().Get()
            for target in product.GetCameraRel().GetTargets():
                resolutions[target] = (int(resolution[0]), int(resolution[1])) if resolution else None
    for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
        if prim.IsA(UsdGeom.Mesh):
            _read_mesh_prim(prim, to_scene, contents, where, exact)
        elif (prim.IsA(UsdLux.DomeLight) or prim.IsA(UsdLux.DomeLight_1)) and contents.kg is None:
            if UsdGeom.Imageable(prim).ComputeVisibility() != UsdGeom.Tokens.invisible:
                contents.kg = read_dome(prim, to_scene, DEFAULT_CUBE, where, exact)
        elif prim.IsA(UsdGeom.Camera) and not prim.IsInstanceProxy():
            contents.cameras.append(read_camera(prim, to_scene, resolutions.get(prim.GetPath()), where, exact))
    return contents


def _read_mesh_prim(prim: Usd.Prim, to_scene: np.ndarray, contents: StageContents, where: str, exact: bool) -> None:
    imageable = UsdGeom.Imageable(prim)
    instance = _instance_root(prim)
    role = _role(instance) or _role(prim) or "surface"
    if imageable.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy):
        return
    if imageable.ComputeVisibility() == UsdGeom.Tokens.invisible and not (exact and role == "window"):
        return  # hidden in the tool; the export's own hidden windows come back as windows
    piece = read_mesh(prim, instance)
    world = _world(prim, to_scene)
    piece.positions = _transform(piece.positions, world)
    if np.linalg.det(world[:3, :3]) < 0:
        piece.faces = piece.faces[:, ::-1].copy()  # a mirror flips the winding back
    material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    key = str(material.GetPath()) if material else ""
    if key not in contents.materials:
        contents.materials[key] = read_material(material, where, exact)
    contents.pieces.append(ImportedPiece(str(prim.GetPath()), piece, key, light_radiance(prim), role,
                                         world if instance is not None else None))


# ---------------------------------------------------------------------------------------------
# The mesh: pieces back into one, in the scene's order where it is known
# ---------------------------------------------------------------------------------------------


def _fresh(keys: list, sizes: list[int]) -> list[np.ndarray]:
    """Fill the pieces without scene numbers with new numbers after every known one."""
    known = [k for k in keys if k is not None and len(k)]
    next_key = int(max(k.max() for k in known)) + 1 if known else 0
    out = []
    for k, size in zip(keys, sizes):
        if k is None:
            k = np.arange(next_key, next_key + size)
            next_key += size
        out.append(np.asarray(k, np.int64))
    return out


def _settle(keys: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
    """Keys where a repeated key gets a new one after all: for vertices when its data differs (a
    moved copy of a prim), for faces always (a copied prim's faces are faces of their own)."""
    _, first, inverse = np.unique(keys, return_index=True, return_inverse=True)
    first_of_row = first[inverse.reshape(-1)]
    if rows is None:
        clash = first_of_row != np.arange(len(keys))
    else:
        clash = ~np.all(rows == rows[first_of_row], axis=1)
    keys = keys.copy()
    keys[clash] = keys.max(initial=-1) + 1 + np.arange(clash.sum())
    return keys


def assemble(pieces: list[MeshPiece]) -> tuple[Mesh, np.ndarray]:
    """One mesh from pieces in the world frame, and the piece of each of its faces. Vertices and
    faces are sorted by their scene numbers (pieces without numbers get new ones at the end);
    a vertex shared by pieces is merged when they agree on it."""
    if not pieces:
        raise ValueError("assemble: no meshes")
    vertex_keys = np.concatenate(_fresh([p.vertex_ids for p in pieces], [len(p.positions) for p in pieces]))
    positions = np.concatenate([p.positions for p in pieces]).astype(np.float32)
    uvs = np.concatenate([p.uvs for p in pieces]).astype(np.float32)
    vertex_keys = _settle(vertex_keys, np.hstack([positions, uvs]).view(np.int32))  # compare bits
    _, first, vertex_of_row = np.unique(vertex_keys, return_index=True, return_inverse=True)
    vertex_of_row = vertex_of_row.reshape(-1)

    offsets = np.cumsum([0] + [len(p.positions) for p in pieces])
    faces = np.concatenate([vertex_of_row[p.faces + offsets[k]] for k, p in enumerate(pieces)])
    owner = np.concatenate([np.full(len(p.faces), k) for k, p in enumerate(pieces)])
    instance = np.concatenate([np.full(len(p.faces), p.instance_id, np.int32) for p in pieces])
    face_keys = np.concatenate(_fresh([p.face_ids for p in pieces], [len(p.faces) for p in pieces]))
    face_keys = _settle(face_keys)
    order = np.argsort(face_keys, kind="stable")
    mesh = Mesh(positions=positions[first], faces=faces[order].astype(np.int32), uvs=uvs[first],
                instance_ids=instance[order])
    return mesh, owner[order]


# ---------------------------------------------------------------------------------------------
# The maps: one atlas from the materials of the pieces
# ---------------------------------------------------------------------------------------------


def _atlas_shape(sources: MaterialSources) -> tuple[int, int]:
    for source in (sources.kd, sources.ks, sources.ke, sources.ka, sources.kw):
        shape = texture_shape(source)
        if shape is not None:
            return shape
    return DEFAULT_ATLAS


def _texels_of(mesh: Mesh, faces: np.ndarray, shape) -> np.ndarray:
    return np.unique(face_texels(mesh.uvs, mesh.faces[faces], shape)[1])


def bake_maps(mesh: Mesh, owner: np.ndarray, contents: StageContents, exact: bool, where: str) -> dict[str, np.ndarray]:
    """The atlas maps: the main material's, with each piece's own material baked under its faces
    where it differs, and mesh lights' radiance (standard view, or an edited intensity)."""
    weights = {}
    for k, piece in enumerate(contents.pieces):
        weights[piece.material] = weights.get(piece.material, 0) + int((owner == k).sum())
    base_key = max(weights, key=weights.get)
    base = contents.materials[base_key]
    shape = _atlas_shape(base)
    maps = evaluate_maps(base, shape)
    evaluated = {base_key: maps}
    for k, piece in enumerate(contents.pieces):
        sources = contents.materials[piece.material]
        differs = [name for name in MAP_NAMES if sources.key(name) != base.key(name)]
        if not differs:
            continue
        if piece.material not in evaluated:
            evaluated[piece.material] = evaluate_maps(sources, shape)
        texels = _texels_of(mesh, np.flatnonzero(owner == k), shape)
        for name in differs:
            flat = maps[name].reshape(shape[0] * shape[1], -1)  # a view: the maps are contiguous
            flat[texels] = evaluated[piece.material][name].reshape(flat.shape)[texels]
        log.info("%s: material %s differs from %s in %s: baked under its %d faces", piece.prim, piece.material,
                 base_key, ", ".join(differs), int((owner == k).sum()))
    _apply_lights(mesh, owner, contents, maps, shape, exact)
    return maps


def _apply_lights(mesh, owner, contents: StageContents, maps: dict, shape, exact: bool) -> None:
    """Mesh lights: in the standard view ke is the light's uniform radiance; in the exact view an
    edited colour x intensity rescales the texture-exact ke (an untouched one leaves it alone)."""
    for k, piece in enumerate(contents.pieces):
        if piece.light is None:
            continue
        faces = np.flatnonzero(owner == k)
        texels = _texels_of(mesh, faces, shape)
        ke = maps["ke"].reshape(-1, 3)
        if not exact:
            ke[texels] = piece.light
            continue
        current = mean_radiance(mesh, Maps(**{n: maps[n] for n in MAP_NAMES}, kg=np.zeros((6, 1, 1, 3))), faces)
        if np.allclose(current, piece.light, rtol=1e-5, atol=1e-7):
            continue
        ratio = np.where(current > 0, piece.light / np.where(current > 0, current, 1.0), 0.0)
        ke[texels] = np.where(current > 0, ke[texels] * ratio, piece.light)
        log.info("%s: light radiance %s is not its emission's mean %s: ke scaled to match", piece.prim,
                 np.round(piece.light, 4).tolist(), np.round(current, 4).tolist())


def _clip(maps: dict[str, np.ndarray], where: str) -> dict[str, np.ndarray]:
    """Values another tool may have put outside our ranges, clipped (MILO Eq. 2-3) with a warning."""
    limits = {"kd": (0, 1), "ks": (0, 1), "ka": (1e-6, 1), "ke": (0, np.inf), "kw": (0, 1)}
    out = {}
    for name, (lo, hi) in limits.items():
        values = np.nan_to_num(np.asarray(maps[name], np.float32), nan=lo, posinf=hi, neginf=lo)
        clipped = np.clip(values, lo, hi).astype(np.float32)
        if np.any(np.abs(clipped - values) > 1e-6):
            log.warning("%s: %s had values outside [%g, %g]: clipped", where, name, lo, hi)
        out[name] = clipped
    return out


# ---------------------------------------------------------------------------------------------
# The stage
# ---------------------------------------------------------------------------------------------


def _metadata(contents: StageContents, usd_path: Path, exact: bool) -> dict:
    """Names and poses of what the stage holds, so that exporting the scene again keeps them."""
    names, poses = {}, []
    for item in contents.pieces:
        instance = item.piece.instance_id
        if item.role in ("surface", "instance") and instance not in names:
            names[instance] = Path(item.prim).parent.name if item.instance_pose is not None else Path(item.prim).name
        if item.instance_pose is not None and instance not in {p["instance_id"] for p in poses}:
            poses.append({"instance_id": int(instance), "mask_value": int(instance), "registered": True,
                          "T_obj2world": item.instance_pose.tolist()})
    metadata = {"imported_from": str(usd_path), "exact": exact,
                "instances": [{"instance_id": int(k), "name": v} for k, v in sorted(names.items())]}
    if poses:
        metadata["poses"] = {"convention": "p_world = T_obj2world @ [p_obj, 1]; T_obj2world row-major 4x4; "
                             "object frame = the USD prototype's", "scale": "as the USD stage",
                             "instances": sorted(poses, key=lambda p: p["instance_id"])}
    return metadata


def import_usd(usd_path, out_dir, exact: bool = True) -> Scene:
    """Read a USD stage (module docstring) and write it as a scene directory to `out_dir`."""
    usd_path = Path(usd_path)
    if not usd_path.is_file():
        raise SceneError(usd_path, "(file)", "an existing USD file (.usda, .usdc, .usd)")
    try:
        stage = Usd.Stage.Open(str(usd_path))
    except Tf.ErrorException as exc:
        raise SceneError(usd_path, "(file)", f"a USD stage that opens ({str(exc).strip()})") from None
    where = str(usd_path)
    contents = read_stage(stage, where, exact)
    if not contents.pieces:
        raise SceneError(usd_path, "(stage)", "at least one visible UsdGeom.Mesh")
    mesh, owner = assemble([item.piece for item in contents.pieces])
    maps = _clip(bake_maps(mesh, owner, contents, exact, where), where)
    kg = contents.kg if contents.kg is not None else np.zeros((6, DEFAULT_CUBE, DEFAULT_CUBE, 3), np.float32)
    names = [c.name for c in contents.cameras]
    if len(set(names)) != len(names):
        raise SceneError(usd_path, "cameras", "cameras with distinct names (invrender:colmap:name or prim name)")
    scene = Scene(mesh=mesh, maps=Maps(**maps, kg=kg.astype(np.float32)), cameras=contents.cameras)
    write_scene(out_dir, scene, metadata=_metadata(contents, usd_path, exact))
    log.info("imported %s -> %s: %d faces, %d cameras, atlas %dx%d%s", usd_path, out_dir, len(mesh.faces),
             len(scene.cameras), *maps["kd"].shape[:2], "" if exact else " (standard schemas only)")
    return scene

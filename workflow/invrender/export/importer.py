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
- Duplicates: instances become poses again (scene.json metadata `poses`, in poses.json's form), so the
  next export instances them again; the names of prims become instance names.
- A stage with objects (prims with invrender:role "object", the export of a v2 scene) comes back
  as a v2 scene instead (`objects_to_scene`): each object with its transform and its meshes in its
  own frame, the instances of one prototype sharing one mesh, one material set per material.

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

from ..scene.atomic import check_output
from ..scene.format import write_scene
from ..scene.packing import object_transform, pack_scene
from ..scene.regions import face_texels
from ..scene.types import Atlas, Maps, Mesh, Scene, SceneError, SceneObject
from . import schema
from .cameras import read_camera
from .geometry import MeshPiece, authored_value, read_mesh
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


def _instance_root(prim: Usd.Prim) -> Usd.Prim | None:
    while prim and prim.IsInstanceProxy():
        prim = prim.GetParent()
    return prim if prim and prim.IsInstance() else None


def _role(prim: Usd.Prim | None) -> str | None:
    attr = prim.GetAttribute(schema.ROLE) if prim else None
    return str(attr.Get()) if attr and attr.HasAuthoredValue() else None


def read_stage(stage: Usd.Stage, where: str, exact: bool = True, meshes: bool = True) -> StageContents:
    """Everything the scene needs from a stage (module docstring); without `meshes` only the sky
    and the cameras (a v2 stage's objects are read by read_objects)."""
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
        if prim.IsA(UsdGeom.Mesh) and meshes:
            _read_mesh_prim(prim, to_scene, contents, where, exact)
        elif (prim.IsA(UsdLux.DomeLight) or prim.IsA(UsdLux.DomeLight_1)) and contents.kg is None:
            if UsdGeom.Imageable(prim).ComputeVisibility() != UsdGeom.Tokens.invisible:
                contents.kg = read_dome(prim, to_scene, DEFAULT_CUBE, where, exact)
        elif prim.IsA(UsdGeom.Camera) and not prim.IsInstanceProxy():
            contents.cameras.append(read_camera(prim, to_scene, resolutions.get(prim.GetPath()), where, exact))
    return contents


def _drawn(prim: Usd.Prim, role: str, exact: bool) -> bool:
    """A mesh the scene keeps: not a guide or proxy, and visible (the export's own hidden
    windows come back as windows in the exact view)."""
    imageable = UsdGeom.Imageable(prim)
    if imageable.ComputePurpose() in (UsdGeom.Tokens.guide, UsdGeom.Tokens.proxy):
        return False
    return imageable.ComputeVisibility() != UsdGeom.Tokens.invisible or (exact and role == "window")


def _read_mesh_prim(prim: Usd.Prim, to_scene: np.ndarray, contents: StageContents, where: str, exact: bool) -> None:
    instance = _instance_root(prim)
    role = _role(instance) or _role(prim) or "surface"
    if not _drawn(prim, role, exact):
        return
    piece = read_mesh(prim, instance)
    world = _world(prim, to_scene)
    piece.positions = object_transform(piece.positions, world)
    if np.linalg.det(world[:3, :3]) < 0:
        piece.faces = piece.faces[:, ::-1].copy()  # a mirror flips the winding back
    material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
    key = str(material.GetPath()) if material else ""
    if key not in contents.materials:
        contents.materials[key] = read_material(material, where, exact)
    contents.pieces.append(
        ImportedPiece(
            str(prim.GetPath()), piece, key, light_radiance(prim), role, world if instance is not None else None
        )
    )


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
    mesh = Mesh(
        positions=positions[first], faces=faces[order].astype(np.int32), uvs=uvs[first], instance_ids=instance[order]
    )
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
        log.info(
            "%s: material %s differs from %s in %s: baked under its %d faces",
            piece.prim,
            piece.material,
            base_key,
            ", ".join(differs),
            int((owner == k).sum()),
        )
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
        log.info(
            "%s: light radiance %s is not its emission's mean %s: ke scaled to match",
            piece.prim,
            np.round(piece.light, 4).tolist(),
            np.round(current, 4).tolist(),
        )


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
# v2 stages: objects (Xforms with role "object") back into objects and material sets
# ---------------------------------------------------------------------------------------------


@dataclass
class ImportedObject:
    prim: Usd.Prim
    world: np.ndarray  # object-to-world in the scene's frame
    pieces: list[ImportedPiece] = field(default_factory=list)  # positions in the object's frame


def has_objects(stage: Usd.Stage) -> bool:
    """A stage exported from a v2 scene: some prim stands for an object."""
    return any(_role(prim) == "object" for prim in stage.Traverse())


def _object_of(prim: Usd.Prim) -> Usd.Prim | None:
    """The object a mesh belongs to: its nearest ancestor with role "object" (through instances)."""
    while prim and not prim.IsPseudoRoot():
        if _role(prim) == "object":
            return prim
        prim = prim.GetParent()
    return None


def _relative(prim: Usd.Prim, owner: Usd.Prim) -> np.ndarray:
    """4x4 from `prim`'s frame to `owner`'s: the local transforms in between (none: identity)."""
    m = np.eye(4)
    while prim != owner:
        if prim.IsA(UsdGeom.Xformable):
            local = np.array(UsdGeom.Xformable(prim).GetLocalTransformation(Usd.TimeCode.Default()), np.float64)
            if not np.array_equal(local, np.eye(4)):
                m = local.T @ m  # USD matrices act on row vectors
        prim = prim.GetParent()
    return m


def read_objects(stage: Usd.Stage, where: str, exact: bool, materials: dict) -> list[ImportedObject]:
    """Every object of a v2 stage with its meshes in its own frame; a mesh outside every object
    (added in another tool) is an object of its own, placed where it is. `materials` collects
    the sources of every bound material by path."""
    to_scene = stage_to_scene(stage)
    objects: dict[str, ImportedObject] = {}
    for prim in stage.Traverse(Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)):
        if _role(prim) == "object" and not prim.IsInstanceProxy():
            objects[str(prim.GetPath())] = ImportedObject(prim, _world(prim, to_scene))
        if not prim.IsA(UsdGeom.Mesh) or not _drawn(prim, _role(prim) or "surface", exact):
            continue
        owner = _object_of(prim) or prim
        if str(owner.GetPath()) not in objects:
            objects[str(owner.GetPath())] = ImportedObject(owner, _world(owner, to_scene))
        piece = read_mesh(prim)
        relative = _relative(prim, owner)
        piece.positions = object_transform(piece.positions, relative)
        if np.linalg.det(relative[:3, :3]) < 0:
            piece.faces = piece.faces[:, ::-1].copy()
        material = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        key = str(material.GetPath()) if material else ""
        if key not in materials:
            materials[key] = (read_material(material, where, exact), _set_name(material))
        objects[str(owner.GetPath())].pieces.append(
            ImportedPiece(str(prim.GetPath()), piece, key, light_radiance(prim), _role(prim) or "surface")
        )
    return [obj for obj in objects.values() if obj.pieces]


def _set_name(material: UsdShade.Material | None) -> str:
    if not material:
        return "unbound"
    return authored_value(material.GetPrim(), schema.MATERIAL_SET) or material.GetPrim().GetName()


def _object_maps(obj: ImportedObject, mesh: Mesh, owner: np.ndarray, sources, exact: bool, where: str) -> dict:
    """The maps of an object's material set: its main material's, with its mesh lights applied."""
    shape = _atlas_shape(sources)
    maps = evaluate_maps(sources, shape)
    _apply_lights(mesh, owner, StageContents(pieces=obj.pieces), maps, shape, exact)
    return _clip(maps, where)


def objects_to_scene(stage: Usd.Stage, where: str, exact: bool) -> Scene:
    """A v2 stage as a v2 scene: objects with their transforms (instances of one prototype share
    one mesh), one material set per set name, the sky and the cameras."""
    materials: dict[str, tuple] = {}
    imported = read_objects(stage, where, exact, materials)
    if not imported:
        raise SceneError(where, "(stage)", "at least one visible UsdGeom.Mesh")
    meshes, objects, sets, taken = {}, [], {}, set()
    for obj in imported:
        prototype = str(obj.prim.GetPrototype().GetPath()) if obj.prim.IsInstance() else str(obj.prim.GetPath())
        if prototype not in meshes:
            meshes[prototype] = assemble([item.piece for item in obj.pieces])
        mesh, owner = meshes[prototype]
        weights = {}
        for k, item in enumerate(obj.pieces):
            weights[item.material] = weights.get(item.material, 0) + int((owner == k).sum())
        main = max(weights, key=weights.get)
        others = sorted(set(weights) - {main})
        if others:
            log.warning(
                "%s: meshes bound to %s besides its material %s: a v2 object has one material set, theirs are not kept",
                obj.prim.GetPath(),
                ", ".join(others),
                main,
            )
        sources, set_name = materials[main]
        if set_name not in sets:
            sets[set_name] = Atlas(**_object_maps(obj, mesh, owner, sources, exact, where))
        name = authored_value(obj.prim, schema.OBJECT_NAME) or obj.prim.GetName()
        unique, k = name, 1
        while unique in taken:
            unique, k = f"{name}_{k}", k + 1
        taken.add(unique)
        instance_id = authored_value(obj.prim, schema.INSTANCE_ID)
        objects.append(
            SceneObject(
                unique,
                mesh,
                set_name,
                obj.world,
                instance_id=None if instance_id is None else int(instance_id),
                emission_sides=str(authored_value(obj.prim, schema.EMISSION_SIDES) or "two"),
            )
        )
    contents = read_stage(stage, where, exact, meshes=False)
    kg = contents.kg if contents.kg is not None else np.zeros((6, DEFAULT_CUBE, DEFAULT_CUBE, 3), np.float32)
    return pack_scene(objects, sets, kg.astype(np.float32), contents.cameras)


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
            poses.append(
                {
                    "instance_id": int(instance),
                    "mask_value": int(instance),
                    "registered": True,
                    "T_obj2world": item.instance_pose.tolist(),
                }
            )
    metadata = {
        "imported_from": str(usd_path),
        "exact": exact,
        "instances": [{"instance_id": int(k), "name": v} for k, v in sorted(names.items())],
    }
    if poses:
        metadata["poses"] = {
            "convention": "p_world = T_obj2world @ [p_obj, 1]; T_obj2world row-major 4x4; "
            "object frame = the USD prototype's",
            "scale": "as the USD stage",
            "instances": sorted(poses, key=lambda p: p["instance_id"]),
        }
    return metadata


def _check_camera_names(cameras: list, usd_path) -> None:
    names = [c.name for c in cameras]
    if len(set(names)) != len(names):
        raise SceneError(usd_path, "cameras", "cameras with distinct names (invrender:colmap:name or prim name)")


def import_usd(usd_path, out_dir, exact: bool = True) -> Scene:
    """Read a USD stage (module docstring) and write it as a scene directory to `out_dir`."""
    check_output(out_dir, "scene")  # before the work, not after it
    usd_path = Path(usd_path)
    if not usd_path.is_file():
        raise SceneError(usd_path, "(file)", "an existing USD file (.usda, .usdc, .usd)")
    try:
        stage = Usd.Stage.Open(str(usd_path))
    except Tf.ErrorException as exc:
        raise SceneError(usd_path, "(file)", f"a USD stage that opens ({str(exc).strip()})") from None
    where = str(usd_path)
    if has_objects(stage):
        scene = objects_to_scene(stage, where, exact)
        _check_camera_names(scene.cameras, usd_path)
        write_scene(out_dir, scene, metadata={"imported_from": str(usd_path), "exact": exact})
        log.info(
            "imported %s -> %s: %d objects, %d faces, %d cameras",
            usd_path,
            out_dir,
            len(scene.objects),
            len(scene.mesh.faces),
            len(scene.cameras),
        )
        return scene
    contents = read_stage(stage, where, exact)
    if not contents.pieces:
        raise SceneError(usd_path, "(stage)", "at least one visible UsdGeom.Mesh")
    mesh, owner = assemble([item.piece for item in contents.pieces])
    maps = _clip(bake_maps(mesh, owner, contents, exact, where), where)
    kg = contents.kg if contents.kg is not None else np.zeros((6, DEFAULT_CUBE, DEFAULT_CUBE, 3), np.float32)
    _check_camera_names(contents.cameras, usd_path)
    scene = Scene(mesh=mesh, maps=Maps(**maps, kg=kg.astype(np.float32)), cameras=contents.cameras)
    write_scene(out_dir, scene, metadata=_metadata(contents, usd_path, exact))
    log.info(
        "imported %s -> %s: %d faces, %d cameras, atlas %dx%d%s",
        usd_path,
        out_dir,
        len(mesh.faces),
        len(scene.cameras),
        *maps["kd"].shape[:2],
        "" if exact else " (standard schemas only)",
    )
    return scene

"""The `export` stage: a scene directory -> export/scene.usda (+ scene.usdc) with textures/.

    /Scene                      Xform, the default prim (meters, +Y up)
      Looks/atlas               the UsdPreviewSurface material of the atlas (materials.py)
      Geometry/<name>           one Mesh per instance id of the plain surfaces (room, table, ...)
      Geometry/window_<k>       window openings: invisible meshes (lights.py)
      Geometry/<object>_<id>    duplicates: instanceable Xforms at their poses (instancing.py)
      Prototypes/<object>       class: the shared mesh and its material
      Lights/sky                DomeLight of kg
      Lights/light_<k>          emitting regions: meshes with UsdLux.MeshLightAPI
      Cameras/<image>           one UsdGeom.Camera per input view (cameras.py)
    /Render/Products/<image>    the resolution and pixel aspect ratio of each camera

A v2 scene (objects, material sets) is written by `write_objects_stage` instead: Looks/<set> per
material set, Geometry/<object> an Xform with the object's transform and its mesh below it (split
as above), objects sharing a mesh and a set as instanceable references to Prototypes/<object>.

Everything is written into a temporary directory beside the output, checked with the
validators usdchecker runs (check.py), and renamed into place: a failure leaves nothing behind.
"""

from __future__ import annotations

import json
import logging
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdRender, UsdShade

from ..scene.atomic import atomic_dir
from ..scene.format import load_scene, read_scene_json
from ..scene.poses import read_poses, validate_poses
from ..scene.regions import classify_faces
from ..scene.types import Maps, Scene, SceneError, SceneObject
from . import schema
from .cameras import author_camera, author_render_product
from .check import validate_usd
from .geometry import MeshPiece, author_mesh, connected_faces, piece_of, write_indices
from .instancing import Duplicates, find_duplicates
from .lights import author_dome, author_mesh_light, mean_radiance, write_sky
from .materials import TEXTURES, author_material, write_textures

__all__ = ["Part", "plan_parts", "export_usd", "write_stage"]

log = logging.getLogger(__name__)

ROOT = "/Scene"
OBJECT = "object"  # the prototype's name and the stem of its instances' names


@dataclass
class Part:
    """A plain mesh prim of the export: a piece of the scene and what it stands for."""

    name: str
    role: str  # "surface", "window" or "light"
    piece: MeshPiece
    radiance: np.ndarray | None = None  # lights: the mean radiance


def _prim_name(text: str, taken: set) -> str:
    name = Tf.MakeValidIdentifier(re.sub(r"\.[A-Za-z0-9]+$", "", str(text)) or "_")
    unique, k = name, 1
    while unique in taken:
        unique, k = f"{name}_{k}", k + 1
    taken.add(unique)
    return unique


def instance_names(metadata: dict) -> dict[int, str]:
    """Names of the scene's instance ids from its metadata (the room generator lists them)."""
    names = {0: "surfaces"}
    for entry in metadata.get("instances", []) if isinstance(metadata, dict) else []:
        if isinstance(entry, dict) and isinstance(entry.get("instance_id"), int) and entry.get("name"):
            names[entry["instance_id"]] = str(entry["name"])
    return names


def plan_parts(scene: Scene, names: dict[int, str], instanced: np.ndarray) -> list[Part]:
    """Split the faces not `instanced` into plain prims: surfaces and windows per instance id, and
    lights per instance id and connected emitting region."""
    mesh = scene.mesh
    regions = classify_faces(scene)
    ids = mesh.instance_ids if mesh.instance_ids is not None else np.zeros(len(mesh.faces), np.int32)
    surface = ~(regions["hole"] | regions["emitter"] | instanced)
    parts, taken = [], set()
    for instance in np.unique(ids[surface]):
        faces = np.flatnonzero(surface & (ids == instance))
        label = names.get(int(instance), f"{OBJECT}_{instance}")
        parts.append(Part(_prim_name(label, taken), "surface", piece_of(mesh, faces, instance)))
    for k, instance in enumerate(np.unique(ids[regions["hole"]])):
        faces = np.flatnonzero(regions["hole"] & (ids == instance))
        parts.append(Part(_prim_name(f"window_{k}", taken), "window", piece_of(mesh, faces, instance)))
    emitting = regions["emitter"] & ~instanced
    for instance in np.unique(ids[emitting]):
        faces = np.flatnonzero(emitting & (ids == instance))
        region = piece_of(mesh, faces)
        groups = connected_faces(region.positions, region.faces)
        for group in range(groups.max() + 1):
            light_faces = faces[groups == group]
            number = sum(part.role == "light" for part in parts)
            parts.append(
                Part(
                    _prim_name(f"light_{number}", taken),
                    "light",
                    piece_of(mesh, light_faces, instance),
                    radiance=mean_radiance(mesh, scene.maps, light_faces),
                )
            )
    return parts


def _clipping(scene: Scene, camera) -> tuple[float, float]:
    """Near and far planes holding the whole mesh (our renderer has none; other tools need them)."""
    lo, hi = scene.mesh.positions.min(axis=0), scene.mesh.positions.max(axis=0)
    corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    far = float(np.linalg.norm(corners - camera.center, axis=1).max()) * 1.1
    diagonal = float(np.linalg.norm(hi - lo))
    return max(1e-4, 1e-3 * diagonal), max(far, 1e-3)


def _role(prim: Usd.Prim, role: str) -> None:
    prim.CreateAttribute(schema.ROLE, Sdf.ValueTypeNames.Token, custom=True).Set(role)


def _bind(prim: Usd.Prim, material: UsdShade.Material) -> None:
    UsdShade.MaterialBindingAPI.Apply(prim).Bind(material)


def _instance_matrix(T: np.ndarray) -> Gf.Matrix4d:
    return Gf.Matrix4d(np.asarray(T, np.float64).T.tolist())  # USD multiplies row vectors


def write_stage(
    path: Path,
    scene: Scene,
    parts: list[Part],
    duplicates: Duplicates | None,
    names: dict[int, str],
    files: dict[str, str],
) -> Usd.Stage:
    """Author the whole stage (module docstring) at `path`; textures are already in `files`."""
    stage = _new_stage(path)
    material = author_material(stage, f"{ROOT}/Looks/atlas", files)
    for part in parts:
        folder = "Lights" if part.role == "light" else "Geometry"
        _author_part(stage, f"{ROOT}/{folder}/{part.name}", part, material)

    if duplicates is not None:
        prototype = f"{ROOT}/Prototypes/{OBJECT}"
        stage.CreateClassPrim(f"{ROOT}/Prototypes")  # abstract: drawn only through its instances
        UsdGeom.Xform.Define(stage, prototype)
        UsdGeom.Scope.Define(stage, f"{prototype}/Looks")
        proto_material = author_material(stage, f"{prototype}/Looks/atlas", files)
        proto_mesh = author_mesh(stage, f"{prototype}/mesh", duplicates.prototype, keep_indices=False)
        _bind(proto_mesh.GetPrim(), proto_material)
        taken = {part.name for part in parts}
        for copy in duplicates.copies:
            name = _prim_name(names.get(copy.instance_id, f"{OBJECT}_{copy.instance_id}"), taken)
            instance = UsdGeom.Xform.Define(stage, f"{ROOT}/Geometry/{name}")
            instance.AddTransformOp().Set(_instance_matrix(copy.T))
            prim = instance.GetPrim()
            prim.GetReferences().AddInternalReference(prototype)
            prim.SetInstanceable(True)
            _role(prim, "instance")
            write_indices(
                prim,
                MeshPiece(
                    duplicates.prototype.positions,
                    duplicates.prototype.uvs,
                    duplicates.prototype.faces,
                    copy.face_ids,
                    copy.vertex_ids,
                    copy.instance_id,
                ),
            )

    _author_sky_and_cameras(stage, scene, files)
    return stage


def _new_stage(path: Path) -> Usd.Stage:
    """The empty stage: meters, +Y up, /Scene with its Looks, Geometry and Lights."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageMetersPerUnit(stage, UsdGeom.LinearUnits.meters)
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    root = UsdGeom.Xform.Define(stage, ROOT)
    stage.SetDefaultPrim(root.GetPrim())
    stage.GetRootLayer().customLayerData = {schema.LAYER_KEY: {"format": schema.FORMAT, "version": schema.VERSION}}
    UsdGeom.Scope.Define(stage, f"{ROOT}/Looks")
    UsdGeom.Xform.Define(stage, f"{ROOT}/Geometry")
    UsdGeom.Scope.Define(stage, f"{ROOT}/Lights")
    return stage


def _author_part(stage: Usd.Stage, path: str, part: Part, material: UsdShade.Material) -> None:
    mesh = author_mesh(stage, path, part.piece)
    _role(mesh.GetPrim(), part.role)
    _bind(mesh.GetPrim(), material)
    if part.role == "window":
        mesh.MakeInvisible()  # an opening: the dome shows through it
    if part.role == "light":
        author_mesh_light(mesh.GetPrim(), part.radiance)


def _author_sky_and_cameras(stage: Usd.Stage, scene: Scene, files: dict) -> None:
    """The dome (when write_sky wrote its textures into `files`) and the cameras."""
    if "sky" in files:
        author_dome(stage, f"{ROOT}/Lights/sky", files["sky"], scene.maps.kg.shape[1], files["sky_cube"])

    if scene.cameras:
        UsdGeom.Scope.Define(stage, f"{ROOT}/Cameras")
        settings = UsdRender.Settings.Define(stage, "/Render/Settings")
        taken, products = set(), []
        for camera in scene.cameras:
            name = _prim_name(camera.name, taken)
            camera_path = f"{ROOT}/Cameras/{name}"
            author_camera(stage, camera_path, camera, _clipping(scene, camera))
            products.append(author_render_product(stage, f"/Render/Products/{name}", camera_path, camera).GetPath())
        settings.CreateProductsRel().SetTargets(products)
        settings.CreateCameraRel().SetTargets(
            UsdRender.Product(stage.GetPrimAtPath(products[0])).GetCameraRel().GetTargets()
        )
        stage.SetMetadata("renderSettingsPrimPath", "/Render/Settings")


def _object_prim(stage: Usd.Stage, path: str, obj: SceneObject) -> Usd.Prim:
    """An object's Xform: its transform, and what USD has no word for (name, instance id, sides)."""
    xform = UsdGeom.Xform.Define(stage, path)
    xform.AddTransformOp().Set(_instance_matrix(obj.transform))
    prim = xform.GetPrim()
    _role(prim, "object")
    prim.CreateAttribute(schema.OBJECT_NAME, Sdf.ValueTypeNames.String, custom=True).Set(obj.name)
    prim.CreateAttribute(schema.EMISSION_SIDES, Sdf.ValueTypeNames.Token, custom=True).Set(obj.emission_sides)
    if obj.instance_id is not None:
        prim.CreateAttribute(schema.INSTANCE_ID, Sdf.ValueTypeNames.Int, custom=True).Set(int(obj.instance_id))
    return prim


def _set_material(stage: Usd.Stage, path: str, files: dict[str, str], name: str) -> UsdShade.Material:
    material = author_material(stage, path, files)
    material.GetPrim().CreateAttribute(schema.MATERIAL_SET, Sdf.ValueTypeNames.String, custom=True).Set(name)
    return material


def write_objects_stage(
    path: Path, scene: Scene, files: dict[str, dict[str, str]], sky: dict
) -> tuple[Usd.Stage, list[Part]]:
    """Author a v2 scene (docs/export.md, "Scenes with objects"): one material per material set
    (`files[set]` its textures), one Xform per object with its transform, its mesh in its own
    frame below it split into surfaces, windows and lights as a v1 scene's is; objects sharing a
    mesh and a material set reference one prototype as instanceable prims."""
    stage = _new_stage(path)
    atlases = scene.packing.unpack_atlas(scene.maps)
    groups: dict[tuple, list[SceneObject]] = {}
    for obj in scene.objects:
        groups.setdefault((id(obj.mesh), obj.material), []).append(obj)
    plain = {obj.material for members in groups.values() if len(members) == 1 for obj in members}
    instanced = {obj.material for members in groups.values() if len(members) > 1 for obj in members} - plain
    taken = set()  # /Scene/Looks: every set but those only instances use (their prototypes hold them)
    looks = {
        name: _set_material(stage, f"{ROOT}/Looks/{_prim_name(name, taken)}", files[name], name)
        for name in atlases
        if name not in instanced
    }
    taken, authored = set(), []
    for members in groups.values():
        first = members[0]
        content = Scene(first.mesh, Maps(**vars(atlases[first.material]), kg=scene.maps.kg))
        parts = plan_parts(content, {0: "surfaces"}, np.zeros(len(first.mesh.faces), bool))
        authored += parts
        if len(members) == 1:
            prim = _object_prim(stage, f"{ROOT}/Geometry/{_prim_name(first.name, taken)}", first)
            for part in parts:
                _author_part(stage, f"{prim.GetPath()}/{part.name}", part, looks[first.material])
            continue
        if not stage.GetPrimAtPath(f"{ROOT}/Prototypes"):
            stage.CreateClassPrim(f"{ROOT}/Prototypes")  # abstract: drawn only through its instances
        prototype = f"{ROOT}/Prototypes/{_prim_name(first.name, set())}"
        UsdGeom.Xform.Define(stage, prototype)
        UsdGeom.Scope.Define(stage, f"{prototype}/Looks")
        material = _set_material(
            stage, f"{prototype}/Looks/{_prim_name(first.material, set())}", files[first.material], first.material
        )
        for part in parts:
            _author_part(stage, f"{prototype}/{part.name}", part, material)
        for obj in members:
            prim = _object_prim(stage, f"{ROOT}/Geometry/{_prim_name(obj.name, taken)}", obj)
            prim.GetReferences().AddInternalReference(prototype)
            prim.SetInstanceable(True)
    _author_sky_and_cameras(stage, scene, sky)
    return stage, authored


def _poses_of(poses_path, metadata: dict, where) -> list[dict]:
    if poses_path is not None:
        return validate_poses(read_poses(poses_path), poses_path)
    if isinstance(metadata, dict) and "poses" in metadata:
        return validate_poses(metadata["poses"], Path(where) / "scene.json")
    return []


def export_usd(scene_dir, out_dir, usdc: bool = False, poses=None, instancing: bool = True) -> dict:
    """Export a scene directory to `out_dir` (scene.usda, scene.usdc with `usdc`, textures/,
    export.json). Duplicates are instanced from `poses` (a poses.json), else from the poses in
    scene.json's metadata, unless `instancing` is off. Returns the summary written to export.json."""
    scene_dir, out_dir = Path(scene_dir), Path(out_dir)
    scene = load_scene(scene_dir)  # every bad or missing input stops here, before anything is written
    if scene.version == 2:  # its instances are its objects sharing a mesh: no poses to read
        if poses is not None:
            log.warning("%s is a v2 scene: its objects are its instances, %s is not read", scene_dir, poses)
        return _export_objects(scene, scene_dir, out_dir, usdc)
    metadata = read_scene_json(scene_dir).get("metadata", {})
    names = instance_names(metadata)
    pose_list = _poses_of(poses, metadata, scene_dir) if instancing else []
    diagonal = float(np.linalg.norm(np.ptp(scene.mesh.positions, axis=0)))
    regions = classify_faces(scene)
    duplicates = find_duplicates(
        scene.mesh, pose_list, ~(regions["hole"] | regions["emitter"]), tolerance=1e-5 * max(1.0, diagonal)
    )
    instanced = duplicates.face_mask(len(scene.mesh.faces)) if duplicates else np.zeros(len(scene.mesh.faces), bool)
    parts = plan_parts(scene, names, instanced)

    def author(tmp: Path):
        files = write_textures(scene.maps, tmp / TEXTURES)
        files.update(_write_sky(scene, tmp))
        stage = write_stage(tmp / "scene.usda", scene, parts, duplicates, names, files)
        return stage, lambda layers: _summary(scene, parts, duplicates, layers)

    return _export(scene_dir, out_dir, usdc, author)


def _write_sky(scene: Scene, tmp: Path) -> dict:
    """The dome's textures (none for a black sky): {"sky": lat-long, "sky_cube": exact cube}."""
    return write_sky(scene.maps.kg, tmp, TEXTURES) if np.any(scene.maps.kg > 0) else {}


def _export_objects(scene: Scene, scene_dir: Path, out_dir: Path, usdc: bool) -> dict:
    """A v2 scene's export: textures/<set>/ per material set, then write_objects_stage."""

    def author(tmp: Path):
        files = {}
        for name, atlas in scene.packing.unpack_atlas(scene.maps).items():
            written = write_textures(atlas, tmp / TEXTURES / name)
            files[name] = {
                key: f"./{TEXTURES}/{name}/{Path(rel).name}" for key, rel in written.items()
            }  # its own folder
        stage, parts = write_objects_stage(tmp / "scene.usda", scene, files, _write_sky(scene, tmp))
        return stage, lambda layers: _objects_summary(scene, parts, layers)

    return _export(scene_dir, out_dir, usdc, author)


def _export(scene_dir: Path, out_dir: Path, usdc: bool, author) -> dict:
    """Author into a temporary directory (`author(tmp)` -> stage, summary of the layers), save,
    validate, write export.json and rename into place."""
    try:
        with atomic_dir(out_dir, kind="export") as tmp:
            stage, summarise = author(tmp)
            layers = ["scene.usda", "scene.usdc"] if usdc else ["scene.usda"]
            _save(stage, tmp, layers)
            for layer in layers:
                errors = validate_usd(tmp / layer)
                if errors:
                    raise RuntimeError(f"export of {scene_dir}: {layer} fails validation: " + "; ".join(errors))
            summary = summarise(layers)
            (tmp / "export.json").write_text(json.dumps(summary, indent=2, allow_nan=False) + "\n", encoding="utf-8")
    except OSError as exc:
        raise SceneError(out_dir, "(output directory)", f"a location that can be written ({exc})") from None
    log.info("exported %s -> %s: %s", scene_dir, out_dir, json.dumps(summary["prims"]))
    return summary


def _save(stage: Usd.Stage, directory: Path, layers: list[str]) -> None:
    """Save the layer (and its crate copy); USD reports a failed write as a Tf error."""
    try:
        stage.GetRootLayer().Save()
        for name in layers[1:]:
            stage.GetRootLayer().Export(str(directory / name))
    except Tf.ErrorException as exc:
        raise OSError(f"USD could not write {directory}: {exc}") from None


def _summary(scene: Scene, parts: list[Part], duplicates: Duplicates | None, layers: list[str]) -> dict:
    count = lambda role: sum(part.role == role for part in parts)
    return {
        "format": schema.FORMAT,
        "version": schema.VERSION,
        "layers": layers,
        "validation": "no errors (UsdValidation: the validators usdchecker runs)",
        "prims": {
            "surfaces": count("surface"),
            "windows": count("window"),
            "lights": count("light"),
            "instances": len(duplicates.copies) if duplicates else 0,
            "cameras": len(scene.cameras),
            "dome": bool(np.any(scene.maps.kg > 0)),
        },
        "faces": int(len(scene.mesh.faces)),
        "instanced_faces": int(sum(len(c.face_ids) for c in duplicates.copies)) if duplicates else 0,
        "lights": [
            {
                "name": part.name,
                "faces": int(len(part.piece.faces)),
                "mean_radiance": [round(float(v), 6) for v in part.radiance],
            }
            for part in parts
            if part.role == "light"
        ],
    }


def _objects_summary(scene: Scene, parts: list[Part], layers: list[str]) -> dict:
    count = lambda role: sum(part.role == role for part in parts)
    meshes = {}
    for obj in scene.objects:
        meshes.setdefault((id(obj.mesh), obj.material), []).append(obj.name)
    return {
        "format": schema.FORMAT,
        "version": schema.VERSION,
        "layers": layers,
        "validation": "no errors (UsdValidation: the validators usdchecker runs)",
        "prims": {
            "objects": len(scene.objects),
            "prototypes": sum(len(v) > 1 for v in meshes.values()),
            "instances": sum(len(v) for v in meshes.values() if len(v) > 1),
            "surfaces": count("surface"),
            "windows": count("window"),
            "lights": count("light"),
            "cameras": len(scene.cameras),
            "dome": bool(np.any(scene.maps.kg > 0)),
        },
        "faces": int(len(scene.mesh.faces)),
        "material_sets": sorted(scene.packing.rects),
    }


run = export_usd  # the stage contract's entry point (stage.py:run); export_usd is the API's name

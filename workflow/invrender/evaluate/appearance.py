"""The shared material and the light of a duplicates scene against the truth (SfD section
4: Table 1's single-view column, Table 2's appearance columns).

SfD's text says only "PSNR to evaluate albedo, and MSE to quantify roughness and environmental
lighting"; its released code (github.com/Tianhang-Cheng/SfD, utils/evaluate.py and
trainer/train_material.py) says how, and this follows it where our scenes allow:

- Albedo PSNR: both albedos clipped to [0, 1] and gamma-encoded, x^(1/2.2); each channel of the
  recovered one scaled by sum(truth) / sum(recovered) over the compared points (the code's
  ``align_channel``: albedo and light are known only up to a factor per channel from one image,
  kd * kg stays), clipped again; PSNR = 10 log10(1 / MSE). SfD writes it with and without the
  scale and does not say which Table 1 holds; both are here, ``psnr_db`` the scaled one (as the
  prior work it follows, InvRender and NeRFactor, report).
- Roughness MSE: SfD's roughness r is Disney's (GGX alpha = r^2); ours is ka = Beckmann alpha^2,
  so r = ka^(1/4). ``mse`` is on r as the text says; the code gamma-encodes r first
  (``mse_gamma``, r^(1/2.2)). No scale: roughness has no ambiguity.
- Env MSE: both skies on a 512 x 256 lat-long grid of directions (the code's size and grid:
  ``MaterialTrainRunner.evaluate_envmap`` draws its sky at linspace(0, pi, 256) x linspace(pi, -pi,
  512) over the whole sphere, ``upper_hemi`` off, and resizes the true map to it), clipped to
  [0, 1] and gamma-encoded, the plain mean over the grid's pixels (which counts the poles more,
  as the code's does) and channels; no scale (the code has none). So the paper's figure covers
  the ground below the horizon too, as ``mse`` does. A sun clips to 1 there, as in
  SfD's. Also on the sphere (``mse_solid_angle``, each cube texel by its solid angle), linear
  (``mse_linear``, ``maps.kg_mse``), and with the albedo's scale undone (``mse_with_albedo_scale``:
  the recovered kg divided by the per-channel linear factor, (channel scale)^2.2, that the albedo
  needed, the other half of the kd * kg ambiguity; ours, not SfD's), and above the horizon only
  (``mse_above_horizon``: the synthetic worlds' +Y up; the grid's rows above it): below it the
  support hides the sky from every copy, so no image says anything of it. The two skies are compared
  in the same world directions without any alignment: the recovered world is the photograph's
  camera's, whose axes are the truth's for a synthetic capture (its scale and origin may differ:
  directions do not see them), so a recovered sky turned by R scores the turned sky's error.

Where SfD renders the albedo from test views and compares pixels, here it is compared on the
surface, as the MILO evaluation does (``correspond.py``): every covered texel of the recovered
object's atlas is a 3D point of the recovered mesh in the recovered object frame, taken to the
true object frame by the mesh alignment p = s Q p' + o (``duplicates.mesh_metrics``), and looked
up on the true object's surface (the true texel at the nearest point). So texels count by area,
faces the photograph never shows included. The support (a recovered object with the material set
"support", in the recovered world) is compared the same way with the true floor, through the
similarity of the copies' centres (recovered world -> true world, ``duplicates.translation_metrics``).

Relighting: ``relight.py``.
"""

from __future__ import annotations

import json
import logging
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..scene.atlas import rasterize_atlas
from ..scene.cubemap import as_cube, latlong_directions, lookup_cube
from ..scene.edits import set_sky
from ..scene.format import load_scene, read_scene_json
from ..scene.mesh_io import read_mesh
from ..scene.packing import object_transform
from ..scene.poses import read_poses
from ..scene.types import Atlas, Camera, Mesh, Scene, SceneError
from . import figures, relight
from .correspond import correspond
from .duplicates import poses_by_id, surface_centroid
from .maps import ball_subset, kg_mse, kg_on_common_cube, truth_in_recovered_layout
from .metrics import mse, psnr, tone_map

__all__ = [
    "PAPER_TABLE1_SINGLE_VIEW",
    "PAPER_TABLE2_COLOR_BOX",
    "GAMMA",
    "Similarity",
    "Alignment",
    "Side",
    "recovered_side",
    "truth_side",
    "display",
    "roughness",
    "albedo_errors",
    "roughness_errors",
    "surface_errors",
    "aligned_correspondence",
    "env_errors",
    "read_training",
    "check_sides",
    "evaluate",
]

log = logging.getLogger(__name__)

# SfD (NeurIPS 2023) Table 1, single view ("Ours"): one image of the duplicates.
PAPER_TABLE1_SINGLE_VIEW = {
    "albedo_psnr_db": 17.629,
    "roughness_mse": 0.062,
    "relighting_psnr_db": 21.374,
    "env_mse": 0.052,
    "chamfer": 0.034,  # the paper's units (unstated)
}
# SfD Table 2 (left), the "color box" scenes by number of copies: the appearance columns.
PAPER_TABLE2_COLOR_BOX = {
    "6": {"albedo_psnr_db": 18.48, "roughness_mse": 0.13, "env_mse": 0.116},
    "8": {"albedo_psnr_db": 18.26, "roughness_mse": 0.09, "env_mse": 0.172},
    "10": {"albedo_psnr_db": 18.99, "roughness_mse": 0.09, "env_mse": 0.204},
    "20": {"albedo_psnr_db": 19.22, "roughness_mse": 0.09, "env_mse": 0.063},
    "30": {"albedo_psnr_db": 19.69, "roughness_mse": 0.07, "env_mse": 0.119},
    "50": {"albedo_psnr_db": 18.56, "roughness_mse": 0.08, "env_mse": 0.153},
    "60": {"albedo_psnr_db": 16.45, "roughness_mse": 0.14, "env_mse": 0.150},
}
GAMMA = 2.2  # SfD's tonemap_img: x^(1/2.2), not the sRGB curve
ENV_GRID = (512, 256)  # SfD's env map size, width x height
OBJECT_SET, SUPPORT_SET = relight.OBJECT_SET, relight.SUPPORT_SET


# --- frames ----------------------------------------------------------------------------------------


@dataclass
class Similarity:
    """p -> scale R p + t."""

    scale: float
    rotation: np.ndarray
    translation: np.ndarray

    @classmethod
    def identity(cls) -> Similarity:
        return cls(1.0, np.eye(3), np.zeros(3))

    def matrix(self) -> np.ndarray:
        out = np.eye(4)
        out[:3, :3], out[:3, 3] = self.scale * np.asarray(self.rotation, np.float64), self.translation
        return out

    def mesh(self, mesh: Mesh) -> Mesh:
        """The mesh moved, UVs and instance ids kept."""
        positions = object_transform(np.asarray(mesh.positions, np.float64), self.matrix())
        return Mesh(positions, mesh.faces, mesh.uvs, mesh.instance_ids)


@dataclass
class Alignment:
    """The mesh alignment: the recovered object frame in the true one (p = s Q p' + o) and the
    recovered world in the true one (the similarity of the copies' centres)."""

    object: Similarity
    world: Similarity

    @classmethod
    def from_metrics(cls, metrics: dict) -> Alignment | None:
        """From ``duplicates.evaluate``'s document; None without a mesh alignment (fewer than
        three registered copies matched)."""
        mesh = metrics.get("mesh")
        if mesh is None:
            return None
        a, w = mesh["alignment"], metrics["poses"]["after"]["translation"]["similarity"]
        as_array = lambda v: np.asarray(v, np.float64)  # noqa: E731
        return cls(
            Similarity(float(a["scale"]), as_array(a["rotation"]), as_array(a["offset"])),
            Similarity(float(w["scale"]), as_array(w["rotation"]), as_array(w["translation"])),
        )


@dataclass
class Side:
    """One side of the comparison: the shared object (its mesh in the object frame, its atlas,
    its pose per copy), the support (a world mesh and its atlas, or None), the sky, the
    photograph's camera and the whole scene (rendered in place)."""

    object_mesh: Mesh
    object_atlas: Atlas
    poses: dict
    support_mesh: Mesh | None
    support_atlas: Atlas | None
    kg: np.ndarray
    camera: Camera
    scene: Scene


def _camera(scene: Scene, where) -> Camera:
    if not scene.cameras:
        raise SceneError(where, "cameras", "the photograph's camera")
    return scene.cameras[0]


def _world_mesh(objects) -> Mesh:
    """Objects (each with UVs in one material set) as one world-space mesh."""
    positions, faces, uvs, offset = [], [], [], 0
    for obj in objects:
        positions.append(object_transform(obj.mesh.positions, obj.transform))
        faces.append(np.asarray(obj.mesh.faces, np.int64) + offset)
        uvs.append(np.asarray(obj.mesh.uvs, np.float32))
        offset += len(obj.mesh.positions)
    return Mesh(np.concatenate(positions), np.concatenate(faces).astype(np.int32), np.concatenate(uvs))


def _v2_side(scene: Scene, where) -> Side:
    """A v2 scene's copies (material set "object", one shared mesh) and support (set "support")."""
    sets = scene.packing.unpack_atlas(scene.maps)
    copies = [o for o in scene.objects if o.material == OBJECT_SET]
    if not copies:
        raise SceneError(where, "objects", f'copies of the object with the material set "{OBJECT_SET}"')
    if len({id(o.mesh) for o in copies}) != 1:
        raise SceneError(where, "objects", f'copies ("{OBJECT_SET}") that instance one shared mesh')
    poses = {int(o.instance_id if o.instance_id is not None else k + 1): o.transform for k, o in enumerate(copies)}
    supports = [o for o in scene.objects if o.material == SUPPORT_SET]
    return Side(
        object_mesh=copies[0].mesh,
        object_atlas=sets[OBJECT_SET],
        poses=poses,
        support_mesh=_world_mesh(supports) if supports else None,
        support_atlas=sets.get(SUPPORT_SET) if supports else None,
        kg=np.asarray(scene.maps.kg),
        camera=_camera(scene, where),
        scene=scene,
    )


def recovered_side(scene_dir) -> Side:
    """The recovered scene directory (a v2 scene: bake_duplicates' output)."""
    where = Path(scene_dir) / "scene.json"
    scene = load_scene(scene_dir)
    if not scene.objects:
        raise SceneError(where, "version", "a v2 scene of copies instancing one mesh (bake_duplicates' output)")
    return _v2_side(scene, where)


def _faces_of(mesh: Mesh, faces: slice) -> Mesh:
    """The submesh of a face range, its own vertex list."""
    f = np.asarray(mesh.faces)[faces]
    used, inverse = np.unique(f, return_inverse=True)
    return Mesh(np.asarray(mesh.positions)[used], inverse.reshape(-1, 3).astype(np.int32), np.asarray(mesh.uvs)[used])


def truth_side(truth_dir) -> Side:
    """A synthetic capture's ground_truth/: a v2 scene (as the recovered one), or a v1 scene with
    object.ply (the shared object in its frame, UVs in the scene's atlas), poses.json, and the
    floor's face range in scene.json's metadata (the generator's ``floor.faces``) as support."""
    truth_dir = Path(truth_dir)
    scene = load_scene(truth_dir / "scene")
    where = truth_dir / "scene" / "scene.json"
    if scene.objects:
        return _v2_side(scene, where)
    metadata = read_scene_json(truth_dir / "scene").get("metadata") or {}
    floor = (metadata.get("floor") or {}).get("faces")
    atlas = scene.maps.atlas
    return Side(
        object_mesh=read_mesh(truth_dir / "object.ply", require_uvs=True),
        object_atlas=atlas,
        poses=poses_by_id(read_poses(truth_dir / "poses.json"), truth_dir / "poses.json")[0],
        support_mesh=_faces_of(scene.mesh, slice(*floor)) if floor else None,
        support_atlas=atlas if floor else None,
        kg=np.asarray(scene.maps.kg),
        camera=_camera(scene, where),
        scene=scene,
    )


# --- maps on the surface -------------------------------------------------------------------------------


def display(values) -> np.ndarray:
    """SfD's tonemap_img(clip_img(x)): clipped to [0, 1], x^(1/2.2)."""
    return np.clip(np.asarray(values, np.float64), 0.0, 1.0) ** (1.0 / GAMMA)


def roughness(ka) -> np.ndarray:
    """Disney's roughness r (GGX alpha = r^2) of ka = Beckmann alpha^2: r = ka^(1/4)."""
    return np.clip(np.asarray(ka, np.float64), 0.0, 1.0) ** 0.25


def albedo_errors(recovered, truth) -> dict:
    """PSNR of two albedos (n, 3) on SfD's encoding, with its per-channel scale and without."""
    pred, gt = display(recovered), display(truth)
    total = pred.sum(axis=0)
    scale = np.divide(gt.sum(axis=0), total, out=np.ones(3), where=total > 0)
    return {
        "psnr_db": psnr(np.clip(pred * scale, 0.0, 1.0), gt),
        "psnr_db_unaligned": psnr(pred, gt),
        "channel_scale": scale.tolist(),  # on the encoded values
        "linear_scale": (scale**GAMMA).tolist(),  # the same factor on linear albedo
    }


def roughness_errors(recovered_ka, truth_ka) -> dict:
    r, t = roughness(recovered_ka), roughness(truth_ka)
    return {"mse": mse(r, t), "mse_gamma": mse(display(r), display(t))}


def aligned_correspondence(
    mesh: Mesh, shape, similarity: Similarity, truth_mesh: Mesh, truth_shape, max_texels: int | None = None
):
    """The true texel at each covered texel of ``mesh``'s atlas (of ``shape``) once the mesh is
    moved by ``similarity`` into the truth's frame (``correspond.py``); with ``max_texels``, at
    most that many of them at an even stride (a room's atlas holds half a million)."""
    moved = similarity.mesh(mesh)
    texels = rasterize_atlas(moved, *shape)
    if not texels.mask.any():
        raise SceneError("evaluate appearance", "atlas", "a recovered mesh whose UVs cover some texels")
    if max_texels is not None:
        covered = np.flatnonzero(texels.mask)
        mask = np.zeros(texels.mask.size, bool)
        mask[covered[ball_subset(len(covered), max_texels)]] = True
        texels = replace(texels, mask=mask.reshape(texels.mask.shape))
    # The points again in float64 from their barycentrics (summing to 1, so a point on an edge is
    # on it to the last bit): correspond's nudge off shared edges
    # finds a point on its triangle within a millionth of the sample spacing (6e-10 m on a 10 cm
    # box), below what float32 positions hold (4e-9 m at 5 cm); a texel centre on a chart seam
    # then keeps the neighbour across it, another face's texel.
    corners = np.asarray(moved.positions, np.float64)[np.asarray(moved.faces, np.int64)[texels.triangle[texels.mask]]]
    weights = texels.barycentric[texels.mask].astype(np.float64)
    position = np.zeros(texels.position.shape, np.float64)
    position[texels.mask] = np.einsum("nk,nkc->nc", weights / weights.sum(axis=1, keepdims=True), corners)
    texels = replace(texels, position=position)
    return correspond(texels, truth_mesh, truth_shape, recovered_mesh=moved)


def surface_errors(recovered: Atlas, truth: Atlas, corr) -> dict:
    """Albedo and roughness (module docstring) and plain MSEs of kd, ks, ka over the covered
    texels; beside them the same of the best constant guess, each map the truth's mean over the
    surface, which a recovery has to beat by a wide margin."""
    rec = {m: np.asarray(getattr(recovered, m))[corr.mask] for m in ("kd", "ks", "ka")}
    true = {m: corr.truth_values(getattr(truth, m)) for m in ("kd", "ks", "ka")}
    constant = {m: np.broadcast_to(values.mean(axis=0), values.shape) for m, values in true.items()}
    return {
        "albedo": albedo_errors(rec["kd"], true["kd"]),
        "roughness": roughness_errors(rec["ka"], true["ka"]),
        "map_mse": {m: mse(rec[m], true[m]) for m in rec},
        "correspondence": corr.summary(),
        "constant_guess": {
            "albedo": albedo_errors(constant["kd"], true["kd"]),
            "roughness": roughness_errors(constant["ka"], true["ka"]),
            "map_mse": {m: mse(constant[m], true[m]) for m in rec},
        },
    }


# --- the sky ---------------------------------------------------------------------------------------------


def env_errors(recovered_kg, truth_kg, linear_scale=None) -> dict:
    """The env MSEs of the module docstring; ``linear_scale`` (3,): the albedo's per-channel
    linear factor, whose inverse the recovered sky gets for ``mse_with_albedo_scale``."""
    directions = latlong_directions(*ENV_GRID)
    truth = display(lookup_cube(truth_kg, directions))

    def on_grid(kg) -> float:
        return mse(display(lookup_cube(kg, directions)), truth)

    upper = directions[..., 1] > 0
    out = {
        "mse": on_grid(recovered_kg),
        "mse_above_horizon": mse(display(lookup_cube(recovered_kg, directions[upper])), truth[upper]),
        "mse_solid_angle": kg_mse(display(as_cube(recovered_kg)), display(as_cube(truth_kg))),
        "mse_linear": kg_mse(recovered_kg, truth_kg),
        "grid": list(ENV_GRID),
    }
    if linear_scale is not None:
        out["mse_with_albedo_scale"] = on_grid(as_cube(recovered_kg) / np.asarray(linear_scale, np.float64))
    return out


# --- the material stage's cost --------------------------------------------------------------------------


def read_training(path) -> dict | None:
    """{"training_seconds", "peak_memory_mb"} of the material stage's training.json, None when
    there is no such file (no material stage yet); a file without them is refused."""
    if path is None or not Path(path).is_file():
        return None
    try:
        doc = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise SceneError(path, "(document)", f"a readable JSON document ({exc})") from None
    out = {}
    for key in ("training_seconds", "peak_memory_mb"):
        value = doc.get(key) if isinstance(doc, dict) else None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value) or value < 0:
            raise SceneError(path, key, f"a number >= 0, got {value!r}")
        out[key] = float(value)
    return out


# --- the whole comparison ---------------------------------------------------------------------------------


def _surface(out: Path, name: str, recovered: Atlas, truth: Atlas, mesh, similarity, truth_mesh) -> dict:
    corr = aligned_correspondence(mesh, recovered.atlas_shape, similarity, truth_mesh, truth.atlas_shape)
    errors = surface_errors(recovered, truth, corr)
    here = truth_in_recovered_layout(truth, corr)
    for m in ("kd", "ka"):
        figures.map_figure(out / f"{name}_{m}.png", m, getattr(recovered, m), here[m], corr.mask)
    return errors


def _rearranged(recovered: Side, truth: Side, alignment: Alignment, new_poses: dict, sky) -> tuple[Scene, Scene]:
    """Both scenes with the copies at the new poses, in the true world: the truth's object at
    T'_i, the recovered object at T'_i A, the recovered support moved by the world similarity."""
    A, camera = alignment.object.matrix(), relight.scaled_camera(truth.camera)
    ours = relight.placed_scene(
        recovered.object_mesh, recovered.object_atlas, {i: T @ A for i, T in new_poses.items()}, sky, camera,
        recovered.support_mesh, recovered.support_atlas, alignment.world.matrix(),
    )  # fmt: skip
    theirs = relight.placed_scene(
        truth.object_mesh, truth.object_atlas, new_poses, sky, camera, truth.support_mesh, truth.support_atlas
    )
    return ours, theirs


def _in_place(side: Side, sky) -> Scene:
    """The scene as it is under another sky, seen by its (scaled) photograph camera."""
    return replace(set_sky(side.scene, sky), cameras=[relight.scaled_camera(side.camera)])


def _relighting(out: Path, recovered: Side, truth: Side, alignment, spp, seed, device) -> dict:
    """Both scenes under each new sky, in place and rearranged (``relight.py``); figures."""
    new_poses, arrangement = None, {"reason": "no alignment of the recovered object frame"}
    if alignment is not None:
        centroid = surface_centroid(truth.object_mesh)
        new_poses, arrangement = relight.rearranged_poses(truth.object_mesh, truth.poses, centroid, truth.camera, seed)
    rows = {}
    for sky_name, sky in relight.skies().items():
        pairs = {"in_place": (_in_place(recovered, sky), _in_place(truth, sky))}
        if new_poses is not None:
            pairs["rearranged"] = _rearranged(recovered, truth, alignment, new_poses, sky)
        rows[sky_name] = {}
        for name, (ours, theirs) in pairs.items():
            metrics, images = relight.compare(ours, theirs, spp, seed, device)
            rows[sky_name][name] = metrics
            if images is not None:
                _relight_figure(out / f"relight_{sky_name}_{name}.png", *images)
            log.info("relighting under %s, %s: PSNR %s dB", sky_name, name, metrics["psnr_db"])
    return {
        "psnr_db": _mean(rows, "rearranged"),
        "in_place_psnr_db": _mean(rows, "in_place"),
        "noise_floor_psnr_db": _mean(rows, "rearranged", "noise_floor_psnr_db"),
        "skies": rows,
        "arrangement": arrangement,
    }


def _mean(rows: dict, arrangement: str, key: str = "psnr_db") -> float | None:
    values = [r[arrangement][key] for r in rows.values() if arrangement in r and r[arrangement][key] is not None]
    return float(np.mean(values)) if values else None


def _relight_figure(path, ours, truth, mask, exposure) -> None:
    left, right = tone_map(ours, exposure), tone_map(truth, exposure)
    note = f"exposure {exposure:.3g}, sRGB; error over the copies' pixels"
    figures.triptych(path, left, right, ("recovered", "truth"), mask=mask, note=note)


def check_sides(recovered: Side, truth: Side) -> None:
    """What the comparison needs of the two sides that each alone does not show: one image size."""
    if (recovered.camera.width, recovered.camera.height) != (truth.camera.width, truth.camera.height):
        raise SceneError(
            "evaluate appearance",
            "camera",
            f"the photograph's {truth.camera.width} x {truth.camera.height}, got "
            f"{recovered.camera.width} x {recovered.camera.height}",
        )


def evaluate(
    recovered: Side,
    truth: Side,
    alignment: Alignment | None,
    out_dir,
    spp: int = 64,
    seed: int = 0,
    device=None,
    chamfer: dict | None = None,
    training: dict | None = None,
) -> dict:
    """metrics.json's "appearance" section (the module docstring and ``relight.py``), figures in
    ``out_dir``. ``chamfer``: the pose and shape evaluation's mesh metrics (``duplicates.mesh_metrics``) for the table;
    ``training``: the material stage's time and memory (``read_training``)."""
    out = Path(out_dir)
    check_sides(recovered, truth)
    surfaces = {"object": None, "support": None}
    if alignment is not None:
        surfaces["object"] = _surface(
            out, "object", recovered.object_atlas, truth.object_atlas,
            recovered.object_mesh, alignment.object, truth.object_mesh,
        )  # fmt: skip
        if recovered.support_mesh is not None and truth.support_mesh is not None:
            surfaces["support"] = _surface(
                out, "support", recovered.support_atlas, truth.support_atlas,
                recovered.support_mesh, alignment.world, truth.support_mesh,
            )  # fmt: skip
    albedo = surfaces["object"]["albedo"] if surfaces["object"] else None
    env = env_errors(recovered.kg, truth.kg, None if albedo is None else albedo["linear_scale"])
    kg_ours, kg_truth, _ = kg_on_common_cube(recovered.kg, truth.kg)
    figures.kg_figure(out / "env_kg.png", kg_ours, kg_truth)
    relighting = _relighting(out, recovered, truth, alignment, spp, seed, device)
    ours = {
        "albedo_psnr_db": None if albedo is None else albedo["psnr_db"],
        "roughness_mse": None if albedo is None else surfaces["object"]["roughness"]["mse"],
        "relighting_psnr_db": relighting["psnr_db"],
        "env_mse": env["mse"],
        "chamfer_m": None if chamfer is None else chamfer["chamfer_m"],
        "chamfer_fraction_of_diagonal": None if chamfer is None else chamfer["chamfer_fraction_of_diagonal"],
    }
    copies = str(len(truth.poses))
    return {
        "table1": {"ours": ours, "paper_single_view": PAPER_TABLE1_SINGLE_VIEW},
        "table2": {"copies": len(truth.poses), "paper_color_box": PAPER_TABLE2_COLOR_BOX.get(copies)},
        "conventions": {
            "albedo": "clip [0, 1], x^(1/2.2), per-channel scale sum(truth) / sum(recovered) (SfD's align_channel)",
            "roughness": "r = ka^(1/4) (Disney roughness of Beckmann alpha^2); mse on r, mse_gamma on r^(1/2.2)",
            "env": f"{ENV_GRID[0]} x {ENV_GRID[1]} lat-long directions, clip [0, 1], x^(1/2.2), no scale",
            "relighting": "copies' pixels, exposure from the truth's 99th percentile there, sRGB; same random numbers",
        },
        "alignment": None
        if alignment is None
        else {"object_scale": alignment.object.scale, "world_scale": alignment.world.scale},
        "object": surfaces["object"],
        "support": surfaces["support"],
        "env": env,
        "relighting": relighting,
        "material_stage": training,
    }

"""The `edit` stage (MILO section 4): a list of edits applied to a scene directory and rendered,
and the same edits applied to the true scene when there is one, so the two can be compared.

Every edit is planned (and so checked) for every scene before the first render: a bad list stops
with one SceneError and writes nothing. Then each edited scene is built in turn, its features
decided by render/analysis.py (an inserted lamp turns emission on, a switched-off room turns it
off), and rendered with the scene's cameras or the edit's own:

    out_dir/
      edits.json                   what was done: regions, texel counts, features, files
      <edit>/<camera>.exr, .png    the edited scene
      <edit>/<camera>_truth.exr, _truth.png   the edited truth (with truth_dir; the same
                                   exposure as the scene's preview, so the PNGs compare)

Regions are said in 3D where the two scenes differ in their atlases: a `material` box selects
texels by their 3D point in either scene, and `relight` emitter numbers (the scene's own, in
edits.json) are carried to the truth's regions by nearest centroid.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..render.analysis import analyse, warn_unphysical_albedo
from ..render.renderer import Renderer
from ..scene.atlas import dilate, rasterize_atlas
from ..scene.atomic import atomic_dir, check_output
from ..scene.edits import (
    WHERE,
    edit_material,
    emitter_regions,
    insert_object,
    region_surfaces,
    scale_emission,
    set_sky,
    sphere_mesh,
)
from ..scene.format import SCENE_JSON, load_scene
from ..scene.images import write_exr, write_png_preview
from ..scene.mesh_io import read_mesh
from ..scene.packing import check_transform, object_transform
from ..scene.types import Mesh, Scene, SceneError, require_positive
from .spec import check_edits, edit_view, read_edits

log = logging.getLogger(__name__)

KIND = "edit"  # the output directory's marker
MAX_BOUNCES = 64
BORDER_TEXELS = 2  # a material edit also sets this many rings of empty texels around its region


@dataclass
class Subject:
    """A scene the edits apply to ("scene" or "truth"), and what the plans learn of it once
    (texels' 3D points for material boxes, emitter regions for relights)."""

    role: str
    directory: Path
    scene: Scene
    _texels: object = None
    _emitters: tuple | None = None

    @property
    def texels(self):
        """Each atlas texel's triangle and 3D point (scene/atlas.py), rasterised once."""
        if self._texels is None:
            self._texels = rasterize_atlas(self.scene.mesh, *self.scene.maps.atlas_shape)
        return self._texels

    @property
    def emitters(self) -> tuple[np.ndarray, int, list[dict]]:
        """(labels, count, one record per region: number, texels, surface area and centroid)."""
        if self._emitters is None:
            labels, count = emitter_regions(self.scene)
            areas, centroids = region_surfaces(self.scene, labels, count)
            regions = [
                {
                    "region": i + 1,
                    "texels": int((labels == i + 1).sum()),
                    "area_m2": float(areas[i]),
                    "centroid": None if np.isnan(centroids[i]).any() else centroids[i].tolist(),
                }
                for i in range(count)
            ]
            self._emitters = (labels, count, regions)
        return self._emitters


@dataclass
class Plan:
    """One edit: how to apply it to each subject, what it did there, and which cameras see it."""

    edit: dict
    apply: dict[str, Callable[[Scene], Scene]] = field(default_factory=dict)
    records: dict[str, dict] = field(default_factory=dict)
    cameras: list = field(default_factory=list)


def run(
    scene_dir,
    edits,
    out_dir,
    truth_dir=None,
    spp=64,
    seed=0,
    device=None,
    max_bounces=None,
    progress=True,
) -> list[dict]:
    """Apply each edit of `edits` (a list of dicts, or a YAML/JSON file of them: docs/edit.md) to
    the scene in `scene_dir` (and to the true scene in `truth_dir`), render it, and write
    out_dir (module docstring). Returns edits.json's list."""
    check_output(out_dir, KIND)  # before the work, not after it
    spp = require_positive("edit --spp", "samples per pixel", spp)
    if max_bounces is not None:
        max_bounces = require_positive("edit --max-bounces", "bounces", max_bounces, minimum=0)
        if max_bounces > MAX_BOUNCES:  # the kernels' limit (render/features.py)
            raise SceneError("edit --max-bounces", "bounces", f"at most {MAX_BOUNCES}, got {max_bounces}")
    source = str(edits) if isinstance(edits, (str, Path)) else "config"
    edit_list = check_edits(read_edits(edits) if isinstance(edits, (str, Path)) else edits, source)
    subjects = [Subject("scene", Path(scene_dir), load_scene(scene_dir))]
    if truth_dir is not None:
        subjects.append(Subject("truth", Path(truth_dir), load_scene(truth_dir)))
    plans = [plan_edit(edit, k, subjects, source) for k, edit in enumerate(edit_list)]
    overrides = None if max_bounces is None else {"max_bounces": max_bounces}
    summary = []
    with atomic_dir(Path(out_dir), kind=KIND) as tmp:
        for plan in plans:
            summary.append(render_plan(plan, subjects, Path(tmp), spp, seed, device, overrides, progress))
        document = {"scene": str(scene_dir), "truth": None if truth_dir is None else str(truth_dir)}
        document |= {"spp": spp, "seed": seed, "edits": summary}
        (Path(tmp) / "edits.json").write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    return summary


def render_plan(plan: Plan, subjects, out: Path, spp, seed, device, overrides, progress) -> dict:
    """Build each subject's edited scene, render the plan's cameras, write the images."""
    name = plan.edit["name"]
    (out / name).mkdir()
    entry = {"name": name, "kind": plan.edit["kind"], "edit": plan.edit, "cameras": [], "features": {}}
    exposures = {}
    for subject in subjects:
        edited = plan.apply[subject.role](subject.scene)
        warn_unphysical_albedo(edited.maps, f"{subject.directory} after edit {name}", log)
        features = analyse(edited, overrides=overrides, device=device)
        entry["features"][subject.role] = features.to_json()["features"]
        entry[subject.role] = plan.records[subject.role]
        renderer = Renderer(edited, features, device=device)
        for camera in plan.cameras:
            stem = Path(camera.name).stem
            image = renderer.render(camera, spp=spp, seed=seed, aovs=False, progress=progress)["radiance"]
            suffix = "" if subject.role == "scene" else f"_{subject.role}"
            write_exr(out / name / f"{stem}{suffix}.exr", image)
            # the truth's preview at the scene's exposure: the two PNGs compare by eye
            exposures[stem] = write_png_preview(out / name / f"{stem}{suffix}.png", image, exposures.get(stem))
            log.info("edit %s: rendered %s%s at %d spp", name, stem, suffix, spp)
    entry["cameras"] = [Path(c.name).stem for c in plan.cameras]
    return entry


# ---------------------------------------------------------------------------- planning


def plan_edit(edit: dict, index: int, subjects: list[Subject], source) -> Plan:
    """Check the edit against every subject (applying it once, so that nothing it says can fail
    later) and return how to apply it. A SceneError of scene/edits.py names the edit's field."""
    plan = Plan(edit=edit, cameras=_cameras(edit, index, subjects[0], source))
    prepare = {"relight": _relight, "insert": _insert, "material": _material, "camera": _camera}[edit["kind"]]
    for subject in subjects:
        try:
            apply, record = prepare(edit, index, subject, subjects[0], source)
            apply(subject.scene)  # every check of scene/edits.py, before any render
        except SceneError as error:
            if error.file != WHERE:
                raise
            raise SceneError(source, f"edits[{index}].{error.field}", error.expected) from None
        plan.apply[subject.role], plan.records[subject.role] = apply, record
    return plan


def _cameras(edit: dict, index: int, subject: Subject, source) -> list:
    """The edit's own camera, else the scene's (those named by `cameras`). The truth is rendered
    with the same cameras, so the images compare pixel for pixel."""
    view = edit_view(edit, source, index)
    if view is not None:
        return [view]
    cameras = subject.scene.cameras
    if not cameras:
        raise SceneError(
            subject.directory / SCENE_JSON,
            "cameras",
            f"cameras to render edit {edit['name']!r} (or the edit's `camera`)",
        )
    wanted = edit.get("cameras")
    if wanted is None:
        return list(cameras)
    known = {c.name: c for c in cameras} | {Path(c.name).stem: c for c in cameras}
    missing = [n for n in wanted if n not in known]
    if missing:
        names = ", ".join(Path(c.name).stem for c in cameras[:8])
        raise SceneError(source, f"edits[{index}].cameras", f"cameras of the scene ({names}), got {missing[0]!r}")
    return [known[n] for n in wanted]


def _relight(edit, index, subject: Subject, reference: Subject, source):
    scale, sky, sky_scale = edit.get("emission_scale"), edit.get("sky"), edit.get("sky_scale")
    labels, count, regions = subject.emitters
    region, chosen = None, "all"
    if "emitters" in edit:
        chosen = _chosen_regions(edit, index, subject, reference, source)
        region = np.isin(labels, chosen)
    record = {"emitter_regions": regions, "scaled": chosen, "emission_scale": scale}
    record |= {"sky": sky, "sky_scale": sky_scale}

    def apply(scene: Scene) -> Scene:
        if scale is not None:
            scene = scale_emission(scene, scale, region)
        if sky is not None:
            scene = set_sky(scene, sky)
        if sky_scale is not None:
            scene = set_sky(scene, scene.maps.kg * np.float32(sky_scale))
        return scene

    return apply, record


def _chosen_regions(edit, index, subject: Subject, reference: Subject, source) -> list[int]:
    """The scene's region numbers as given; in the truth, the region whose centroid is nearest to
    each chosen region's (two atlases number their lamps differently)."""
    _, count, _ = reference.emitters
    bad = [i for i in edit["emitters"] if i > count]
    if bad:
        raise SceneError(
            source,
            f"edits[{index}].emitters",
            f"emitter regions of the scene, 1..{count} (edits.json lists them), got {bad[0]}",
        )
    if subject is reference:
        return list(edit["emitters"])
    _, truth_count, truth_regions = subject.emitters
    mine = [r["centroid"] for r in reference.emitters[2] if r["region"] in edit["emitters"] and r["centroid"]]
    theirs = [(r["region"], r["centroid"]) for r in truth_regions if r["centroid"]]
    if not theirs:
        raise SceneError(subject.directory / SCENE_JSON, "ke", f"emitters to match edits[{index}].emitters (none emit)")
    return sorted({min(theirs, key=lambda t: np.linalg.norm(np.subtract(t[1], c)))[0] for c in mine})


def _insert(edit, index, subject: Subject, reference: Subject, source):
    if "mesh" in edit:
        mesh = read_mesh(edit["mesh"], require_uvs=False)
        transform = check_transform(edit.get("transform", np.eye(4)), source, f"edits[{index}].transform")
        uvs = mesh.uvs if mesh.uvs is not None else np.full((len(mesh.positions), 2), 0.5, np.float32)
        mesh = Mesh(object_transform(mesh.positions, transform), mesh.faces, uvs)
    else:
        mesh = sphere_mesh(edit["center"], edit["radius"], edit.get("segments", 32))
    resolution = edit.get("resolution", 8)

    def apply(scene: Scene) -> Scene:
        return insert_object(scene, mesh, edit["material"], edit["name"], resolution)

    record = {"triangles": int(len(mesh.faces)), "texels": resolution * resolution}
    return apply, record


def _material(edit, index, subject: Subject, reference: Subject, source):
    texels = subject.texels
    lo, hi = np.asarray(edit["box"]["min"]), np.asarray(edit["box"]["max"])
    inside = texels.mask & np.all((texels.position >= lo) & (texels.position <= hi), axis=-1)
    if not inside.any():
        raise SceneError(
            source,
            f"edits[{index}].box",
            f"a box holding some surface of {subject.directory} (no atlas texel's 3D point lies in it)",
        )
    # The empty texels next to the region are read too (a nearest lookup near a chart's edge, a
    # packed set's padding): they take the new values with it, or the old ones would show as a seam.
    grown_values, reach = dilate(inside.astype(np.float32), texels.mask, BORDER_TEXELS)
    region = inside | (~texels.mask & reach & (grown_values > 0))
    record = {"texels": int(inside.sum()), "texels_with_border": int(region.sum()), "values": edit["values"]}

    def apply(scene: Scene) -> Scene:
        return edit_material(scene, region, edit["values"])

    return apply, record


def _camera(edit, index, subject: Subject, reference: Subject, source):
    return (lambda scene: scene), {}

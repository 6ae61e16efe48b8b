"""`invrender bench room`: the room mode (PSDR-Room) on the three synthetic layouts of
`invrender synthesize room_photo` (living, bedroom, office) at 1024 x 768, through the room
stages this tree has, a table per result: box, objects, masks, photo, light and material, time
(docs/benchmarks/room.md; docs/benchmarks.md, "Room").

Per layout, each step a stage's Python entry point timed with its peak memory (harness.Ledger,
steps.json in WORK/LAYOUT):

    capture        synthesize room_photo at WIDTH x HEIGHT, CAPTURE_SPP
    room_box       the box (coarse fit, then Eq. 2's refinement); its metrics are the truth's
    room_objects   the object stage, if the package is there (else "missing")
    room_lights    the initial lights and their radiance
    room_materials the material stage, if the package is there (else "missing")
    bake           bake --room: the room scene
    evaluate       evaluate --room at EVALUATE_SPP
    export         the USD export (time only)

Rows: ``stages`` (what the tree's stages give) and ``truth objects`` (the truth's objects taken
into room_box's world through the photo's camera, x_rb = R_rb^T (R_t x + t_t) / s - R_rb^T t_rb:
what the later stages see when the object stage is perfect, so that the lights', materials' and
photo's numbers are not only the empty room's; grey materials: room_materials' atlases are
shaped for the object stage's own placements). A step that stopped with a SceneError ends its
row with the message; the other rows go on.
"""

from __future__ import annotations

import importlib.util
import json
import logging
import os
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from .harness import Ledger, Stopped, format_table, quiet_pyopencl, run_scenes

log = logging.getLogger("invrender.bench")

DEFAULT_WORK = "results/bench/room"
LAYOUTS = ("living", "bedroom", "office")
WIDTH, HEIGHT = 1024, 768
QUICK_WIDTH, QUICK_HEIGHT = 256, 192
CAPTURE_SPP, QUICK_CAPTURE_SPP = 16, 4
EVALUATE_SPP, QUICK_EVALUATE_SPP = 16, 2
OPTIONAL_STAGES = ("room_objects", "room_materials")  # the room stages that may be absent from a tree
ROWS = ("stages", "truth objects")


@dataclass
class Settings:
    mode: str
    scenes: list
    work: str = DEFAULT_WORK
    width: int = WIDTH
    height: int = HEIGHT
    capture_spp: int = CAPTURE_SPP
    evaluate_spp: int = EVALUATE_SPP


def settings_from(quick: bool, scenes, work) -> Settings:
    from .duplicates import _names

    scenes = _names(scenes, list(LAYOUTS), "scenes") or list(LAYOUTS)
    if quick:
        return Settings("quick", scenes, str(work or DEFAULT_WORK + "_quick"), QUICK_WIDTH, QUICK_HEIGHT,
                        QUICK_CAPTURE_SPP, QUICK_EVALUATE_SPP)  # fmt: skip
    return Settings("full", scenes, str(work or DEFAULT_WORK))


def stage_present(name: str) -> bool:
    return importlib.util.find_spec(f"invrender.{name}") is not None


# ---------------------------------------------------------------------------------------------
# Steps
# ---------------------------------------------------------------------------------------------


def make_capture(layout: str, out: Path, width: int, height: int, spp: int) -> None:
    from ..synthesize.room_photo import make_room_photo, write_room_capture

    scene, metadata = make_room_photo({"layout": layout, "camera": {"width": width, "height": height}})
    write_room_capture(scene, metadata, out, spp=spp)


def truth_objects(capture: Path, room_dir: Path, out: Path) -> None:
    """out/objects.json: the truth's objects with T_obj2world in room_box's world (module
    docstring), as room_objects would write them."""
    from ..scene.room_scene import object_transform_of, room_camera

    truth = json.loads((capture / "truth" / "room.json").read_text())
    room = json.loads((room_dir / "room.json").read_text())
    scale = float((room.get("metrics", {}).get("refined") or {}).get("truth_scale") or 1.0)
    cam_t, cam_r = room_camera(truth), room_camera(room)
    to_camera = np.eye(4)
    to_camera[:3, :3], to_camera[:3, 3] = cam_t.R, cam_t.t  # truth world -> camera (meters)
    from_camera = np.eye(4)
    from_camera[:3, :3], from_camera[:3, 3] = cam_r.R.T, -cam_r.R.T @ cam_r.t  # camera -> room_box world
    shrink = np.diag([1 / scale, 1 / scale, 1 / scale, 1.0])
    move = from_camera @ shrink @ to_camera
    objects = [{**o, "T_obj2world": (move @ object_transform_of(o, "truth")).tolist()} for o in truth["objects"]]
    out.mkdir(parents=True, exist_ok=True)
    (out / "objects.json").write_text(json.dumps({"objects": objects, "source": "truth"}, indent=1) + "\n")


def _optional(name: str, ledger: Ledger, output: Path, *args, **kwargs):
    """An issue-16 stage written beside this benchmark: its stage.run(capture, room_dir, out_dir,
    **kwargs) if the package is there; None (reported "missing") if not, or if it stopped (its error kept
    in steps.json: the rows go on without it). Written before that stage landed: its call is
    this benchmark's guess at the stage's entry point, to be checked when it is merged."""
    if not stage_present(name):
        ledger.steps[name] = {"missing": True}
        return None
    try:
        stage = importlib.import_module(f"invrender.{name}.stage")
        ledger.run(name, output, stage.run, *args, **kwargs)
    except Exception as error:  # noqa: BLE001 - a stage written beside this one: its failure is a result
        log.error("bench room: %s stopped: %s", name, error)
        ledger.steps[name] = {**(ledger.steps.get(name) or {}), "error": str(error)}
        return None
    return output


def layout_steps(layout: str, settings: Settings, ledger: Ledger) -> dict:
    """The shared steps of one layout: capture, room_box, room_objects, room_lights,
    room_materials. Returns their folders (None: missing)."""
    from ..room_box import stage as room_box
    from ..room_lights import stage as room_lights

    folder = ledger.path.parent
    capture, room = folder / "capture", folder / "room_box"
    ledger.run("capture", capture, make_capture, layout, capture, settings.width, settings.height, settings.capture_spp)
    ledger.run("room_box", room, room_box.run, capture, room)
    objects = _optional("room_objects", ledger, folder / "room_objects", capture, room, folder / "room_objects")
    lights = folder / "room_lights"
    ledger.run("room_lights", lights, room_lights.run, capture, room, lights)
    materials = _optional(
        "room_materials", ledger, folder / "room_materials", capture, room, folder / "room_materials",
        objects_dir=objects, lights_dir=lights,
    )  # fmt: skip
    return {"capture": capture, "room": room, "objects": objects, "lights": lights, "materials": materials}


def row_steps(row: str, dirs: dict, settings: Settings, ledger: Ledger) -> None:
    from ..bake import room as bake
    from ..evaluate import room as evaluate
    from ..export import stage as export

    folder = ledger.path.parent
    objects, materials = dirs["objects"], dirs["materials"]
    if row == "truth objects":  # room_materials' atlases are shaped for its own objects' unwraps: grey here
        objects, materials = folder / "objects", None
        ledger.run("truth objects", objects, truth_objects, dirs["capture"], dirs["room"], objects)
    ledger.run(
        "bake", folder / "scene", bake.run, dirs["room"], folder / "scene", dirs["lights"], objects,
        materials, dirs["capture"],
    )  # fmt: skip
    ledger.run(
        "evaluate", folder / "report", evaluate.run, folder / "scene", dirs["capture"], dirs["room"],
        folder / "report", objects_dir=dirs["objects"], lights_dir=dirs["lights"], spp=settings.evaluate_spp,
    )  # fmt: skip
    ledger.run("export", folder / "export", export.run, folder / "scene", folder / "export")


def _read(path: Path):
    return json.loads(path.read_text()) if path.exists() else None


def run_scene(layout: str, settings: Settings) -> list[dict]:
    folder = Path(settings.work) / layout
    shared, error, dirs = Ledger(folder), None, None
    try:
        dirs = layout_steps(layout, settings, shared)
    except Stopped as stop:
        error = str(stop)
    rows = []
    for name in ROWS:
        own = Ledger(folder / name.replace(" ", "_"))
        row = {"scene": layout, "row": name, "error": error}
        if error is None:
            try:
                row_steps(name, dirs, settings, own)
            except Stopped as stop:
                row["error"] = str(stop)
                log.error("bench room: %s %s stopped: %s", layout, name, stop)
        row["steps"] = {**shared.steps, **own.steps}
        row["metrics"] = _read(own.path.parent / "report" / "metrics.json")
        row["room_box"] = (_read(folder / "room_box" / "room.json") or {}).get("metrics")
        rows.append(row)
    return rows


# ---------------------------------------------------------------------------------------------
# The tables
# ---------------------------------------------------------------------------------------------


def _get(document, *path):
    for key in path:
        if document is None:
            return None
        document = document.get(key) if isinstance(document, dict) else None
    return document


STEPS = ("capture", "room_box", "room_objects", "room_lights", "room_materials", "bake", "evaluate", "export")
# room_objects' metrics (objects.json "metrics": "coarse" and "refined", each with these means)
OBJECT_KEYS = ("asset_accuracy", "category_accuracy", "position_error", "yaw_error_deg", "scale_error")


def table_row(row: dict) -> dict:
    m, box = row.get("metrics") or {}, row.get("room_box") or {}
    out = {"scene": row["scene"], "row": row["row"], "error": row.get("error")}
    for stage in ("coarse", "refined"):
        out[f"corner_{stage}"] = _get(box, stage, "corner_error")
        out[f"visible_corner_{stage}"] = _get(box, stage, "visible_corner_error")
    out["room_iou_coarse"] = _mean_iou(_get(box, "coarse", "mask_iou"))
    out["room_iou_refined"] = _mean_iou(_get(box, "refined", "mask_iou"))
    for cls, value in (_get(m, "masks", "per_class") or {}).items():
        out[f"iou_{cls}"] = value
    out["iou_mean"] = _get(m, "masks", "mean")
    out["psnr_db"], out["ssim"] = _get(m, "photo", "psnr_db"), _get(m, "photo", "ssim")
    out["power_ratio"] = _get(m, "lights", "power_ratio")
    out["power_truth_w"] = _get(m, "lights", "power_w", "truth", "mean")
    out["radiance_scale"] = _get(m, "lights", "fit", "radiance_scale")
    out["albedo_psnr_db"] = _get(m, "material", "albedo", "psnr_db")
    out["roughness_mse"] = _get(m, "material", "roughness", "mse")
    out["kd_mse"] = _get(m, "material", "map_mse", "kd")
    objects = _get(m, "objects") if row["row"] == "stages" else None
    for key in OBJECT_KEYS:
        for stage in ("coarse", "refined"):
            out[f"{key}_{stage}"] = _get(objects, stage, key)
    steps = row.get("steps") or {}
    for step in STEPS:  # text: a number, or 'missing' (the stage is not in this tree)
        wall = _get(steps, step, "wall_s")
        out[f"{step}_s"] = "missing" if _get(steps, step, "missing") else None if wall is None else f"{wall:.1f}"
    peaks = [s["peak_rss_mb"] for s in steps.values() if isinstance(s, dict) and s.get("peak_rss_mb") is not None]
    out["peak_rss_mb"] = max(peaks) if peaks else None
    return out


def _mean_iou(per_class) -> float | None:
    values = [v for v in (per_class or {}).values() if v is not None]
    return float(np.mean(values)) if values else None


BOX_COLUMNS = [
    ("scene", "layout", "s"),
    ("corner_coarse", "corner error coarse [m]", ".3f"),
    ("corner_refined", "refined [m]", ".3f"),
    ("visible_corner_coarse", "in view coarse [m]", ".3f"),
    ("visible_corner_refined", "refined [m]", ".3f"),
    ("room_iou_coarse", "box IoU coarse", ".3f"),
    ("room_iou_refined", "refined", ".3f"),
]
OBJECT_COLUMNS = [
    ("scene", "layout", "s"),
    ("asset_accuracy_coarse", "retrieval (asset) coarse", ".2f"),
    ("asset_accuracy_refined", "refined", ".2f"),
    ("category_accuracy_refined", "category", ".2f"),
    ("position_error_coarse", "position error coarse [m]", ".3f"),
    ("position_error_refined", "refined [m]", ".3f"),
    ("yaw_error_deg_coarse", "yaw error coarse [deg]", ".1f"),
    ("yaw_error_deg_refined", "refined [deg]", ".1f"),
    ("scale_error_coarse", "scale error coarse", ".3f"),
    ("scale_error_refined", "refined", ".3f"),
    ("room_objects_s", "room_objects [s]", "s"),
]
MASK_COLUMNS = [
    ("scene", "layout", "s"),
    ("row", "objects", "s"),
    *[(f"iou_{c}", c, ".3f") for c in ("wall", "floor", "ceiling", "window", "lamp", "object")],
    ("iou_mean", "mean", ".3f"),
]
PHOTO_COLUMNS = [
    ("scene", "layout", "s"),
    ("row", "objects", "s"),
    ("psnr_db", "photo PSNR [dB]", ".2f"),
    ("ssim", "SSIM", ".3f"),
    ("power_ratio", "light power / truth", ".2f"),
    ("power_truth_w", "truth power [W]", ".1f"),
    ("radiance_scale", "fitted radiance", ".3f"),
    ("albedo_psnr_db", "albedo PSNR [dB]", ".2f"),
    ("roughness_mse", "roughness MSE", ".4f"),
    ("kd_mse", "kd MSE", ".4f"),
]
TIME_COLUMNS = [("scene", "layout", "s"), ("row", "objects", "s")]
TIME_COLUMNS += [(f"{s}_s", f"{s} [s]", "s") for s in STEPS] + [("peak_rss_mb", "peak RSS [MB]", ".0f")]


def write_markdown(out: Path, report: dict) -> str:
    lines, settings = report["table"], report["settings"]
    stages = [line for line in lines if line["row"] == "stages"]
    missing = sorted({s for line in lines for s in ("room_objects", "room_materials") if line[f"{s}_s"] == "missing"})
    text = [
        f"# invrender bench room ({report['mode']}; {report['seconds']:.0f} s)",
        "",
        f"The three layouts of `invrender synthesize room_photo` at {settings['width']} x {settings['height']} "
        f"({settings['capture_spp']} spp), through the room stages of this tree; the room scene (`bake --room`) "
        f"evaluated by `evaluate --room` at {settings['evaluate_spp']} spp. Rows 'stages': what the stages give "
        "('-' where a stage is missing); 'truth objects': the truth's objects placed in room_box's world "
        "through the photo's camera, as a perfect object stage would. "
        + (f"Missing in this tree: {', '.join(missing)} (grey materials kd 0.5, ks 0.04, ka 0.25)." if missing else ""),
        "",
        format_table("Room box: corner error and the refinement's gain (room_box, Eq. 2)", BOX_COLUMNS, stages),
        format_table("Objects: retrieval and pose (room_objects' metrics)", OBJECT_COLUMNS, stages),
        format_table(
            "Mask IoU per class at the photo's camera (the room scene's ids vs the panoptic ids)", MASK_COLUMNS, lines
        ),  # fmt: skip
        format_table("Re-rendered photo, light and material", PHOTO_COLUMNS, lines),
        "Light: the total power into the room (pi * integral of ke dA, plus the windows' sky flux) over the "
        "truth's; material: every texel of walls, floor, ceiling and objects against the truth's texel at the "
        "nearest surface point (albedo PSNR on SfD's encoding with the per-channel scale; roughness MSE on "
        "ka^(1/4)); docs/room.md, 'Evaluation'.",
        "",
        format_table("Time per stage and peak memory", TIME_COLUMNS, lines),
        "Times: wall clock of each stage's Python entry point in this process on this shared 2-core CPU "
        "('missing': the stage is not in this tree; '-': not reached or reused); peak RSS: this process's "
        "resident set while the steps ran. The paper: 'a few minutes' per photo on a GPU.",
        "",
    ]
    text += [f"STOPPED: {line['scene']} {line['row']}: {line['error']}" for line in lines if line["error"]]
    text.append("Machine: " + ", ".join(f"{k}={v}" for k, v in report["machine"].items()))
    text += [f"NOTE: {n}" for n in report["notes"]]
    markdown = "\n".join(text) + "\n"
    (out / "room.md").write_text(markdown)
    return markdown


# ---------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None, scenes=None, work=None):
    """Every layout through the room stages (resuming in `work`), the tables under `out`."""
    quiet_pyopencl()
    started, load_start = time.time(), os.getloadavg()
    settings = settings_from(quick, scenes, work)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    Path(settings.work).mkdir(parents=True, exist_ok=True)

    def run_one(layout):
        log.info("bench room: %s at %d x %d", layout, settings.width, settings.height)
        return run_scene(layout, settings)

    note = f"{QUICK_WIDTH} x {QUICK_HEIGHT}, {QUICK_CAPTURE_SPP} spp photos: checks the plumbing, not accuracy"
    return run_scenes("room", settings, out, run_one, table_row, write_markdown, note, device, (started, load_start))

"""`invrender bench milo`'s independent section: the multiview recovery on rooms that Mitsuba 3
rendered, against trivial baselines, on a tuning split and a held-out split.

A capture rendered by our own kernels shares their bias and noise with the recovery that reads it;
these are rendered by Mitsuba (mitsuba/capture.py). Two layouts: `window` (sun and sky through a
window, two ceiling lamps) and `lamps` (no daylight: the lamps alone). The tuning split is each
layout at seed 0; the held-out split, which no setting was chosen on, is each at another seed
(other textures, furniture and camera jitter) with another sun and another lamp colour.

Per capture, the same evaluate stage scores every arm on the surface against the truth:

- each recovery arm: MILO-Net with the config's preset (`cpu` in config/benchmark.yaml), the
  `texels` preset (the maps optimised texel by texel);
- the per-texel guess: the `texels` model's start before its light-transport passes (each
  texel's observed radiance times one global factor), scored as it is;
- the constant guess: each map the truth's mean over the surface (evaluate's `constant_guess`);
- the floor: the truth resampled onto the recovered atlas (its maps errors are the resampling's,
  its novel views what a perfect recovery renders at this spp).

Writes OUT/milo-independent.md and .json; docs/milo.md reads them.
"""

from __future__ import annotations

import json
import logging
import sys
import time
from pathlib import Path

import numpy as np

from .harness import PeakRSS, capture_geometry, format_table

log = logging.getLogger("invrender.bench")

CAMERAS = {"count": 24, "width": 128, "height": 96}
HOLDOUT = ["view_004.exr", "view_013.exr", "view_020.exr"]
CAPTURE_SPP = 128
EVALUATE_SPP = 128  # 20 evaluations: the config's 512 would take longer than the trainings
# --quick: the plumbing, not a measurement
QUICK = {"cameras": {"count": 6, "width": 24, "height": 18}, "spp": 4, "holdout": ["view_004.exr"], "evaluate_spp": 2}
DARK = {"sky_zenith": [0.0] * 3, "sky_horizon": [0.0] * 3, "ground": [0.0] * 3, "sun_radiance": [0.0] * 3}
LAYOUTS = {"window": {}, "lamps": {"environment": DARK}}
SPLITS = {
    "tuning": {"seed": 0},
    "held-out": {
        "seed": 1,
        "light_color": [1.0, 0.86, 0.68],
        "environment": {"sun_azimuth_deg": 45.0, "sun_elevation_deg": 48.0},
    },
}
RECOVERIES = {"MILO-Net": None, "texels": ("texels", {})}  # None: the config's preset and overrides
# the texels model's start without light transport, unchanged (no windows: finding them is the
# recovery's, and the sun they let in is fitted by rendering)
GUESS = ("texels", {"iterations": 1, "lr_texels": 0.0, "reflectance_passes": 0, "windows": False})
QUICK_ITERATIONS = 2
METRICS = (
    ("material MSE", ("maps", "material_mse"), ".4f"),
    ("kd MSE", ("maps", "map_mse", "kd"), ".4f"),
    ("light maps MSE (x/(1+x))", ("maps", "light_maps_mse"), ".4f"),
    ("light maps MSE, linear", ("maps", "light_maps_mse_linear"), ".3g"),
    ("the same, kg outside the suns' discs", ("maps", "light_maps_mse_linear_outside_sun"), ".3g"),
    ("sun's power, recovered / true", ("maps", "sun", "power_ratio"), ".2f"),
    ("sun's direction error [deg]", ("maps", "sun", "direction_error_deg"), ".1f"),
    ("emitted power, recovered / true", ("maps", "emitted_power_ratio"), ".2f"),
    ("worst lamp's power, abs(recovered / true - 1)", ("maps", "emitters", "worst_ratio_error"), ".2f"),
    ("novel-view PSNR [dB]", ("novel_views", "mean", "psnr_db"), ".2f"),
)


def room_config(layout: str, split: str, cameras: dict = CAMERAS) -> dict:
    """The room generator's config of one capture (synthesize/room.py's keys)."""
    config = {"cameras": dict(cameras), **{k: v for k, v in SPLITS[split].items() if k != "environment"}}
    environment = {**SPLITS[split].get("environment", {}), **LAYOUTS[layout].get("environment", {})}
    return config | ({"environment": environment} if environment else {})


def make_capture(work: Path, layout: str, split: str, config: dict, device, quick: bool = False) -> None:
    """synthesize (Mitsuba's radiance), cameras and geometry of one capture under `work`; a
    stage's output already there (an earlier run's) is kept."""
    from ..cameras import stage as cameras
    from ..mitsuba.capture import mitsuba_capture
    from ..synthesize import stage as synthesize

    if not (work / "capture").exists():
        factory = lambda scene: mitsuba_capture(scene, device)  # noqa: E731
        cameras_, spp = (QUICK["cameras"], QUICK["spp"]) if quick else (CAMERAS, CAPTURE_SPP)
        room = room_config(layout, split, cameras_)
        synthesize.run("room", work / "capture", room, spp=spp, renderer_factory=factory)
    if not (work / "cameras").exists():
        cameras.run(
            work / "capture" / "sparse", work / "cameras", images_dir=work / "capture" / "images", progress=False
        )
    if not (work / "geometry").exists():
        capture_geometry(work, config, False)


def truth_maps(work: Path):
    """The truth's maps resampled onto the recovered atlas (evaluate's correspondence), its sky."""
    from ..evaluate.correspond import DEFAULT_SAMPLES, DEFAULT_SIDE_MARGIN, correspond
    from ..evaluate.maps import truth_in_recovered_layout
    from ..scene.atlas import AtlasTexels, dilate
    from ..scene.format import load_scene
    from ..scene.types import ATLAS_MAPS, Maps

    texels = AtlasTexels.load(work / "geometry" / "atlas.npz")
    truth = load_scene(work / "capture" / "ground_truth" / "scene")
    corr = correspond(texels, truth.mesh, truth.maps.atlas_shape, DEFAULT_SAMPLES, DEFAULT_SIDE_MARGIN)
    resampled = truth_in_recovered_layout(truth.maps, corr)
    grown = {name: dilate(resampled[name], corr.mask, 3)[0] for name in ATLAS_MAPS}  # the padding too
    grown["ka"] = np.maximum(grown["ka"], 1e-3)
    return Maps(**grown, kg=truth.maps.kg)


def sizes(quick: bool) -> dict:
    """The held-out views and the evaluation's spp of a full or a --quick run."""
    return (
        {"holdout": QUICK["holdout"], "spp": QUICK["evaluate_spp"]}
        if quick
        else {"holdout": HOLDOUT, "spp": EVALUATE_SPP}
    )


def recover(work: Path, name: str, preset: str, overrides: dict, device, holdout: list[str]) -> dict:
    """milo with `preset` and `overrides`, bake; the seconds and peak memory of milo."""
    from ..bake import stage as bake
    from ..milo import stage as milo

    arm = work / name
    wall = time.perf_counter()
    with PeakRSS() as memory:
        summary = milo.run(
            work / "geometry",
            work / "cameras",
            work / "cameras" / "images",
            arm / "milo",
            preset=preset,
            overrides={**overrides, "holdout": holdout},
            resume="never",
            device=device,
            progress=False,
        )
    wall = time.perf_counter() - wall
    bake.run(
        arm / "milo" / "maps.npz", work / "geometry", work / "cameras", arm / "scene", arm / "milo" / "training.json"
    )
    return {"milo_wall_s": wall, "training_s": summary["training_seconds"], "peak_rss_mb": memory.peak / 2**20}


def floor_scene(work: Path) -> None:
    """The floor arm's scene: the truth on our atlas, baked like a recovery."""
    from ..bake import stage as bake
    from ..scene.snapshots import write_snapshot

    arm = work / "floor"
    write_snapshot(arm / "maps.npz", truth_maps(work), 0, 0.0)
    bake.run(arm / "maps.npz", work / "geometry", work / "cameras", arm / "scene")


def evaluate_arm(work: Path, name: str, config: dict, device, size: dict) -> dict:
    from ..evaluate import stage as evaluate

    evaluate.run(
        work / name / "scene",
        work / "capture" / "ground_truth" / "scene",
        work / "geometry" / "atlas.npz",
        work / "cameras" / "images",
        work / name / "report",
        holdout=size["holdout"],
        spp=size["spp"],
        seed=config["evaluate"]["seed"],
        device=device,
        progress=False,
    )
    return json.loads((work / name / "report" / "metrics.json").read_text())


def lookup(metrics: dict, path: tuple):
    value = metrics
    for key in path:
        if not isinstance(value, dict) or key not in value:
            return None
        value = value[key]
    return value


def capture_rows(metrics: dict, times: dict) -> list[dict]:
    """One row per metric: each arm's value, the constant guess's where evaluate gives one."""
    rows = []
    for label, path, fmt in METRICS:
        row = {"metric": label, "fmt": fmt}
        for arm, m in metrics.items():
            row[arm] = lookup(m, path)
        constant = lookup(next(iter(metrics.values())), (path[0], "constant_guess", *path[1:]))
        row["constant guess"] = constant
        rows.append(row)
    rows.append({"metric": "training [s]", "fmt": ".0f", **{arm: t["training_s"] for arm, t in times.items()}})
    rows.append({"metric": "peak memory [MB]", "fmt": ".0f", **{arm: t["peak_rss_mb"] for arm, t in times.items()}})
    return rows


def run_capture(work: Path, layout: str, split: str, config: dict, iterations, device, quick: bool) -> dict:
    make_capture(work, layout, split, config, device, quick)
    preset, overrides = config["milo"]["preset"], dict(config["milo"]["overrides"])
    if iterations is not None:
        overrides["iterations"] = int(iterations)
    arms = {name: arm or (preset, overrides) for name, arm in RECOVERIES.items()}
    if quick:
        arms["texels"] = ("texels", {"iterations": int(iterations)})
    size = sizes(quick)
    times = {name: recover(work, name, p, o, device, size["holdout"]) for name, (p, o) in arms.items()}
    recover(work, "per-texel guess", *GUESS, device, size["holdout"])
    floor_scene(work)
    names = [*arms, "per-texel guess", "floor"]
    metrics = {name: evaluate_arm(work, name, config, device, size) for name in names}
    return {
        "layout": layout,
        "split": split,
        "rows": capture_rows(metrics, times),
        "arms": {n: str(work / n) for n in names},
    }


COLUMNS = ("MILO-Net", "texels", "per-texel guess", "constant guess", "floor")


def markdown(captures: list[dict], config: dict, iterations, quick: bool) -> str:
    cameras, spp, size = (
        (QUICK["cameras"], QUICK["spp"], sizes(True)) if quick else (CAMERAS, CAPTURE_SPP, sizes(False))
    )
    preset = config["milo"]["preset"]
    lines = [
        "# invrender bench milo: rooms rendered by Mitsuba 3"
        + (" (--quick: the plumbing, not a measurement)" if quick else ""),
        "",
        f"{cameras['count']} views of {cameras['width']} x {cameras['height']} ({len(size['holdout'])} held out), "
        f"captured by Mitsuba at {spp} spp; MILO-Net: the `{preset}` preset"
        + (f" at {iterations} iterations" if iterations else "")
        + f"; texels: the `texels` preset; floor: the truth on our atlas; evaluate at {size['spp']} spp. "
        "Lower is better but for PSNR.",
        "",
    ]
    for capture in captures:
        table = [
            {"metric": r["metric"], **{c: "-" if r.get(c) is None else format(r[c], r["fmt"]) for c in COLUMNS}}
            for r in capture["rows"]
        ]
        columns = [("metric", "metric", "s")] + [(c, c, "s") for c in COLUMNS]
        lines.append(format_table(f"`{capture['layout']}`, {capture['split']} split", columns, table))
    return "\n".join(lines) + "\n"


def run_study(config: dict, work: Path, out: Path, iterations, quick: bool, device) -> dict:
    """Every layout on both splits; the tables under `out`."""
    if quick and iterations is None:
        iterations = QUICK_ITERATIONS
    captures = []
    for split in SPLITS:
        for layout in LAYOUTS:
            log.info("bench milo: the %s room, %s split", layout, split)
            where = work / ("quick" if quick else "full") / f"{layout}-{split}"
            captures.append(run_capture(where, layout, split, config, iterations, device, quick))
    text = markdown(captures, config, iterations, quick)
    (out / "milo-independent.md").write_text(text)
    report = {"iterations": iterations, "camera": CAMERAS, "capture_spp": CAPTURE_SPP, "captures": captures}
    (out / "milo-independent.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    sys.stdout.write(text)
    return report

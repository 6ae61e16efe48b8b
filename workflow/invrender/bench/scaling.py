"""`invrender bench scaling`: how time and memory grow with triangles, pixels and samples per
pixel, with fitted exponents, so that a bigger scene's cost can be predicted.

Three sweeps, every point measured in its own process (``python -m invrender.bench.scaling
PROBE``), so that its peak memory is its own; docs/benchmarks.md ("Scaling") has a full run and
its reading.

1. **Triangles** (1 k to 1 M, log-spaced): the synthetic room (``synthesize.room``) built with a
   coarse base mesh (``cell`` 0.5 m: 1,090 triangles) and every triangle split into n^2
   (``render.subdivide_mesh``, as bench render's BVH section), so every size is the same room,
   the same image. Per size: the BVH build and the rest of ``HostScene.pack`` (emitter BVH,
   sampling tables), the peak RSS growth while packing, the device buffers' bytes; then at a
   fixed image and spp, B bounces: the forward render and a gradient pass (render +
   ``adjoint.backward`` of an L2 loss, as bench gradients) per sample, and Mitsuba 3's ``path``
   (``llvm_ad_rgb``, through ``invrender.mitsuba``) per sample on the same scene and camera,
   with its scene load (its BVH build). Time per sample, not time to equal error: the two
   estimators differ in variance per sample (bench render has that ratio).
2. **Pixels** (32 x 24 to 512 x 384) at a fixed spp, and 3. **spp** (1 to 256) at a fixed image,
   on the default room (one process for both sweeps): time of a forward render and of a gradient
   pass, and the peak RSS growth of each (glibc's mmap threshold fixed, as bench gradients'
   memory probe, so a pass's buffers show in RSS on every call).

Timing: each runner is warmed up (kernel builds, Mitsuba's JIT), called once more under the
memory poll, then `repeats` times interleaved (A B C, C B A, ...); time = median wall clock.
Fits: t = a N^k by Theil-Sen on log-log (the median of the pairwise slopes; their interquartile
range is the spread), beside least squares with its standard error and the exponent over the
three largest points (where fixed per-call costs no longer flatten the curve). The prediction
(``predict``) scales the per-sample time at N triangles to an image and spp, corrected by the
pixel and spp sweeps' exponents over their largest points.

The harness relies only on public entry points (``HostScene.pack``, ``Renderer``,
``adjoint.backward`` through bench gradients' runner, ``build_bvh``), not on kernel internals.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
from dataclasses import dataclass, replace

import numpy as np
from tqdm import tqdm

from .gradients import PROBE_ENV, InvrenderGradient
from .harness import (
    PeakRSS,
    clock,
    median,
    next_seed_block,
    pairwise_slopes,
    print_probe,
    pyplot,
    quiet_pyopencl,
    room_scene,
    run_probe,
    run_report,
    scene_buffer_bytes,
    start_run,
    write_report,
)
from .render import ROOM_VIEW, MitsubaRunner, subdivide_mesh, subdivisions_for

log = logging.getLogger("invrender.bench")

PROBE_MARK = "SCALEPROBE "
MB = 2**20


@dataclass(frozen=True)
class Settings:
    mode: str
    view: int = ROOM_VIEW
    bounces: int = 3
    repeats: int = 5
    base_cell: float = 0.5  # the room's coarse base mesh for the triangle sweep: 1,090 triangles
    triangles: tuple = (1_000, 4_000, 16_000, 64_000, 250_000, 1_000_000)
    tri_width: int = 128  # the triangle sweep's fixed image and spp
    tri_height: int = 96
    tri_spp: int = 16
    mitsuba: bool = True
    pixels: tuple = ((32, 24), (64, 48), (128, 96), (256, 192), (512, 384))
    pixel_spp: int = 16
    spps: tuple = (1, 4, 16, 64, 256)
    spp_width: int = 128
    spp_height: int = 96
    predict: tuple = (500_000, 640, 480, 256)  # the worked prediction: triangles, width, height, spp


FULL = Settings("full")
QUICK = Settings(
    "quick",
    repeats=2,
    triangles=(1_000, 4_000, 16_000),
    tri_width=32,
    tri_height=24,
    tri_spp=4,
    pixels=((16, 12), (32, 24), (64, 48)),
    pixel_spp=4,
    spps=(1, 2, 4, 8),
    spp_width=32,
    spp_height=24,
)


def scalar_settings(settings: Settings) -> Settings:
    """Mitsuba's scalar_rgb is no peer for throughput (one lane, the Python BSDF plugin per
    sample): invrender is measured alone."""
    return replace(settings, mitsuba=False)


# ---------------------------------------------------------------------------------------------
# Power laws
# ---------------------------------------------------------------------------------------------


def power_law(x, y) -> dict | None:
    """y = a x^k fitted on log-log over the points with y > 0: Theil-Sen (k = median of the
    pairwise slopes, log a = median of log y - k log x) with the slopes' interquartile range,
    least squares with its standard error, and the Theil-Sen exponent over the three largest x.
    None below two usable points."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    keep = np.isfinite(x) & np.isfinite(y) & (x > 0) & (y > 0)
    lx, ly = np.log(x[keep]), np.log(y[keep])
    if len(np.unique(lx)) < 2:
        return None
    order = np.argsort(lx)
    lx, ly = lx[order], ly[order]
    slopes = pairwise_slopes(lx, ly)
    k = median(slopes)
    k_ls, b_ls = np.polyfit(lx, ly, 1)
    n = len(lx)
    se = None
    if n > 2:
        residual = ly - (k_ls * lx + b_ls)
        se = math.sqrt(float(residual @ residual) / (n - 2) / float(((lx - lx.mean()) ** 2).sum()))
    return {
        "k": k,
        "a": math.exp(median(ly - k * lx)),
        "k_q25": float(np.percentile(slopes, 25)),
        "k_q75": float(np.percentile(slopes, 75)),
        "k_ls": float(k_ls),
        "k_ls_se": se,
        "k_top": median(pairwise_slopes(lx[-3:], ly[-3:])),
        "points": n,
    }


def power_law_at(fit: dict, x: float) -> float:
    return fit["a"] * x ** fit["k"]


def loglog_interpolate(xs, ys, x: float) -> float | None:
    """y at x, linear in log-log between the measured points around it; None outside them."""
    xs, ys = np.asarray(xs, np.float64), np.asarray(ys, np.float64)
    if not (xs.min() <= x <= xs.max()) or np.any(ys <= 0):
        return None
    order = np.argsort(xs)
    return float(np.exp(np.interp(math.log(x), np.log(xs[order]), np.log(ys[order]))))


def from_the_points(xs, ys, x: float, fit: dict) -> float | None:
    """y at x from the measured points: log-log interpolation between them, and beyond the
    largest (smallest) y there times (x / x there)^k with the fit's top (overall) exponent: the
    points carry the offsets a single power law misses (fixed costs at small x)."""
    between = loglog_interpolate(xs, ys, x)
    if between is not None or fit is None:
        return between
    xs, ys = np.asarray(xs, np.float64), np.asarray(ys, np.float64)
    end = int(np.argmax(xs)) if x > xs.max() else int(np.argmin(xs))
    k = fit["k_top"] if x > xs.max() else fit["k"]
    return float(ys[end] * (x / xs[end]) ** k)


# ---------------------------------------------------------------------------------------------
# Measuring (inside a probe process)
# ---------------------------------------------------------------------------------------------


class Passes:
    """invrender's forward render and gradient pass (render, L2 loss against a black image,
    ``adjoint.backward``: bench gradients' runner) of one camera, on an already packed scene."""

    name = "invrender"

    def __init__(self, scene, camera, features, host, device=None):
        target = np.zeros((camera.height, camera.width, 3), np.float32)
        self.grad = InvrenderGradient(scene, camera, features, target, device, host=host)
        self.camera = camera
        self._seed = next_seed_block()

    def forward(self, spp: int):
        self._seed += 1
        return self.grad.renderer.render(self.camera, int(spp), self._seed, aovs=False)["radiance"]

    def gradient(self, spp: int):
        return self.grad.gradient(spp)


def measure(runs: dict, spp: int, repeats: int, warm_spp: int = 1) -> dict:
    """Per runner (name -> callable(spp)): one warm-up call at `warm_spp` (kernel builds, JIT),
    one call under the memory poll (peak RSS growth), then `repeats` timed calls interleaved in
    alternating order; median wall and CPU seconds."""
    for run in runs.values():
        run(warm_spp)
    out = {}
    for name, run in runs.items():
        with PeakRSS() as rss:
            run(spp)
        out[name] = {"rss_mb": rss.growth / MB, "walls": [], "cpus": []}
    names = list(runs)
    for rep in range(repeats):
        for name in names if rep % 2 == 0 else names[::-1]:
            _, wall, cpu = clock(runs[name], spp)
            out[name]["walls"].append(wall)
            out[name]["cpus"].append(cpu)
    return {
        name: {"s": median(o["walls"]), "cpu_s": median(o["cpus"]), "rss_mb": o["rss_mb"]} for name, o in out.items()
    }


def pass_row(section: str, camera, spp: int, passes: Passes, stats: dict) -> dict:
    samples = camera.width * camera.height * spp
    f, g = stats["forward"], stats["gradient"]
    return {
        "section": section,
        "width": camera.width,
        "height": camera.height,
        "pixels": camera.width * camera.height,
        "spp": spp,
        "forward_s": f["s"],
        "forward_cpu_s": f["cpu_s"],
        "forward_us_per_sample": 1e6 * f["s"] / samples,
        "forward_cpu_us_per_sample": 1e6 * f["cpu_s"] / samples,
        "gradient_s": g["s"],
        "gradient_cpu_s": g["cpu_s"],
        "gradient_us_per_sample": 1e6 * g["s"] / samples,
        "gradient_cpu_us_per_sample": 1e6 * g["cpu_s"] / samples,
        "backward_s": passes.grad.last.get("backward_s"),
        "forward_rss_mb": f["rss_mb"],
        "gradient_rss_mb": g["rss_mb"],
        # CPU seconds of all the process's threads per wall second: the share of the cores the
        # renderer had (2 on an idle 2-core machine); wall times are trustworthy only near it.
        "cpu_per_wall": f["cpu_s"] / f["s"],
        "load_1min": os.getloadavg()[0],  # the machine's, as the measurement ended
    }


def features_for(scene, settings: Settings, device=None):
    from ..render.analysis import analyse

    return replace(analyse(scene, device=device), max_bounces=settings.bounces)


def triangles_probe(triangles: int, settings: Settings, variant: str | None, device=None) -> dict:
    """One size of the triangle sweep (`python -m invrender.bench.scaling triangles`)."""
    from ..render.bvh import build_bvh, triangle_vertices
    from ..render.scene_buffers import HostScene
    from ..scene.types import Scene

    base, _ = room_scene(settings.tri_width, settings.tri_height, {"cell": settings.base_cell})
    n = subdivisions_for(len(base.mesh.faces), triangles)
    mesh = subdivide_mesh(base.mesh, n)
    scene = Scene(mesh, base.maps, base.cameras)
    camera = scene.cameras[settings.view]
    features = features_for(base, settings, device)  # tessellation changes no effect: the base decides

    with PeakRSS() as whole:
        with PeakRSS() as packing:
            v = triangle_vertices(mesh.positions, mesh.faces)
            bvh, build_s, _ = clock(build_bvh, *v)
            host, rest_s, _ = clock(HostScene.pack, mesh, scene.maps, bvh)
            del v, bvh
        device_bytes, geometry_bytes = scene_buffer_bytes(host)
        passes = Passes(scene, camera, features, host, device)
        runs = {"forward": passes.forward, "gradient": passes.gradient}
        mitsuba = None
        if variant and settings.mitsuba:
            mitsuba = MitsubaRunner(scene, camera, settings.bounces, variant)
            runs["mitsuba"] = mitsuba.render
        # Mitsuba compiles a kernel per spp: every runner warms up at the measured spp.
        stats = measure(runs, settings.tri_spp, settings.repeats, warm_spp=settings.tri_spp)
    row = pass_row("triangles", camera, settings.tri_spp, passes, stats)
    row = {
        "section": "triangles",
        "triangles": int(len(mesh.faces)),
        "subdivision": n,
        "build_s": build_s,
        "pack_rest_s": rest_s,
        "pack_s": build_s + rest_s,
        "pack_rss_mb": packing.growth / MB,
        "device_mb": device_bytes / MB,
        "geometry_mb": geometry_bytes / MB,
        "device_bytes_per_tri": device_bytes / len(mesh.faces),
        **{k: v for k, v in row.items() if k != "section"},
        "peak_rss_mb": whole.peak / MB,
    }
    if mitsuba is not None:
        samples = camera.width * camera.height * settings.tri_spp
        row["mitsuba_convert_s"] = mitsuba.one_time["convert_s"]
        row["mitsuba_load_s"] = mitsuba.one_time["load_s"]
        row["mitsuba_s"] = stats["mitsuba"]["s"]
        row["mitsuba_us_per_sample"] = 1e6 * stats["mitsuba"]["s"] / samples
        row["mitsuba_cpu_us_per_sample"] = 1e6 * stats["mitsuba"]["cpu_s"] / samples
        row["ratio"] = stats["mitsuba"]["s"] / stats["forward"]["s"]
        row["ratio_cpu"] = stats["mitsuba"]["cpu_s"] / stats["forward"]["cpu_s"]
        row["mitsuba_cpu_per_wall"] = stats["mitsuba"]["cpu_s"] / stats["mitsuba"]["s"]
    return row


def image_probe(settings: Settings, device=None) -> dict:
    """The pixel and spp sweeps on the default room, in one process
    (`python -m invrender.bench.scaling image`)."""
    from ..render.scene_buffers import HostScene

    scene, _ = room_scene(settings.spp_width, settings.spp_height)
    features = features_for(scene, settings, device)
    host = HostScene.pack(scene.mesh, scene.maps)
    rows = {"pixels": [], "spp": []}
    for width, height in settings.pixels:
        camera = room_scene(width, height)[0].cameras[settings.view]
        passes = Passes(scene, camera, features, host, device)
        stats = measure({"forward": passes.forward, "gradient": passes.gradient}, settings.pixel_spp, settings.repeats)
        rows["pixels"].append(pass_row("pixels", camera, settings.pixel_spp, passes, stats))
    camera = scene.cameras[settings.view]
    passes = Passes(scene, camera, features, host, device)
    for spp in settings.spps:
        stats = measure({"forward": passes.forward, "gradient": passes.gradient}, spp, settings.repeats)
        rows["spp"].append(pass_row("spp", camera, spp, passes, stats))
    rows["triangles"] = int(len(scene.mesh.faces))
    return rows


# ---------------------------------------------------------------------------------------------
# Sweeps (in this process: one probe process per point)
# ---------------------------------------------------------------------------------------------


def triangle_sweep(settings: Settings, variant: str, device=None) -> list[dict]:
    rows = []
    for triangles in tqdm(settings.triangles, desc="triangles", unit="size", leave=False):
        args = ["triangles", "--triangles", triangles, "--mode", settings.mode]
        args += ["--variant", variant] if settings.mitsuba else []
        args += ["--device", device] if device else []
        rows.append(run_probe(__name__, args, PROBE_MARK, f"scaling probe ({triangles} triangles)", env=PROBE_ENV))
    return rows


def image_sweeps(settings: Settings, device=None) -> dict:
    args = ["image", "--mode", settings.mode] + (["--device", device] if device else [])
    return run_probe(__name__, args, PROBE_MARK, "scaling probe (pixels and spp)", env=PROBE_ENV)


# What is fitted: (sweep, x, quantity, unit); the triangle sweep's Mitsuba rows only if it ran.
FITTED = (
    ("triangles", "triangles", "build_s", "s"),
    ("triangles", "triangles", "pack_rest_s", "s"),
    ("triangles", "triangles", "pack_s", "s"),
    ("triangles", "triangles", "pack_rss_mb", "MB"),
    ("triangles", "triangles", "device_mb", "MB"),
    ("triangles", "triangles", "forward_us_per_sample", "us"),
    ("triangles", "triangles", "forward_cpu_us_per_sample", "CPU us"),
    ("triangles", "triangles", "gradient_us_per_sample", "us"),
    ("triangles", "triangles", "gradient_cpu_us_per_sample", "CPU us"),
    ("triangles", "triangles", "mitsuba_us_per_sample", "us"),
    ("triangles", "triangles", "mitsuba_cpu_us_per_sample", "CPU us"),
    ("triangles", "triangles", "mitsuba_load_s", "s"),
    ("triangles", "triangles", "peak_rss_mb", "MB"),
    ("pixels", "pixels", "forward_s", "s"),
    ("pixels", "pixels", "forward_cpu_s", "CPU s"),
    ("pixels", "pixels", "gradient_s", "s"),
    ("pixels", "pixels", "gradient_cpu_s", "CPU s"),
    ("pixels", "pixels", "forward_rss_mb", "MB"),
    ("pixels", "pixels", "gradient_rss_mb", "MB"),
    ("spp", "spp", "forward_s", "s"),
    ("spp", "spp", "forward_cpu_s", "CPU s"),
    ("spp", "spp", "gradient_s", "s"),
    ("spp", "spp", "gradient_cpu_s", "CPU s"),
    ("spp", "spp", "forward_rss_mb", "MB"),
    ("spp", "spp", "gradient_rss_mb", "MB"),
)


def fit_rows(results: dict) -> list[dict]:
    rows = []
    for sweep, x, quantity, unit in FITTED:
        points = [r for r in results[sweep] if r.get(quantity) is not None]
        fit = power_law([r[x] for r in points], [r[quantity] for r in points]) if points else None
        if fit is not None:
            rows.append({"section": "fits", "sweep": sweep, "x": x, "quantity": quantity, "unit": unit, **fit})
    return rows


def _fit(fits: list[dict], sweep: str, quantity: str) -> dict | None:
    return next((f for f in fits if f["sweep"] == sweep and f["quantity"] == quantity), None)


def sweep_factor(rows: list[dict], x_key: str, per_sample: str, x0: float, x: float) -> float | None:
    """How much a sample costs at x against at x0, from a sweep of `x_key`: its per-sample time
    interpolated log-log at min(x, the largest measured) over that at x0. Beyond the sweep the
    per-sample time is held (fixed per-call costs are spent by then: the sweep's top exponent
    says how close to 1 it got); None if x0 lies outside the sweep."""
    xs, ys = [r[x_key] for r in rows], [r[per_sample] for r in rows]
    at = loglog_interpolate(xs, ys, min(max(x, min(xs)), max(xs)))
    base = loglog_interpolate(xs, ys, x0)
    return None if at is None or base is None else at / base


def predict(results: dict, fits: list[dict], settings: Settings) -> list[dict]:
    """The cost of N triangles at W x H and S spp, on the wall clock and in CPU seconds: the
    triangle sweep's per-sample time at N (`from_the_points`; beside it its power law) times
    W H S, times the image factor: how per-sample time changes from the triangle sweep's image
    and spp to W x H and S, as the pixel and spp sweeps measured it (`sweep_factor`). Mitsuba's
    uses invrender's forward factor (only its triangle sweep is measured). CPU rows also give
    CPU / cores: the wall time when the renderer has every core (PoCL and drjit both use them
    all). Memory: the scene's from the triangle sweep, a pass's from the pixel sweep."""
    triangles, width, height, spp = settings.predict
    pixels = width * height
    p0, s0 = settings.tri_width * settings.tri_height, settings.tri_spp
    cores = os.cpu_count() or 1
    where = {"triangles": triangles, "width": width, "height": height, "spp": spp}
    rows = []
    for clock_name, cpu in (("wall", ""), ("CPU", "cpu_")):
        for kind, per_sample, image_key in (
            ("forward render", f"forward_{cpu}us_per_sample", f"forward_{cpu}us_per_sample"),
            ("gradient pass", f"gradient_{cpu}us_per_sample", f"gradient_{cpu}us_per_sample"),
            ("mitsuba path (forward)", f"mitsuba_{cpu}us_per_sample", f"forward_{cpu}us_per_sample"),
        ):
            fit = _fit(fits, "triangles", per_sample)
            if fit is None:
                continue
            f_p = sweep_factor(results["pixels"], "pixels", image_key, p0, pixels)
            f_s = sweep_factor(results["spp"], "spp", image_key, s0, spp)
            seconds = 1e-6 * pixels * spp * (f_p or 1.0) * (f_s or 1.0)  # per us of a sample at N
            measured = [r for r in results["triangles"] if r.get(per_sample) is not None]
            us = from_the_points([r["triangles"] for r in measured], [r[per_sample] for r in measured], triangles, fit)
            rows.append(
                {
                    "section": "prediction",
                    "what": f"{kind}, {clock_name} [s]",
                    **where,
                    "us_per_sample": us,
                    "pixel_factor": f_p,
                    "spp_factor": f_s,
                    "predicted": us * seconds,
                    "power_law": power_law_at(fit, triangles) * seconds,
                    "all_cores_wall_s": us * seconds / cores if cpu else None,
                }
            )
    for kind, sweep, quantity, x in (
        ("HostScene.pack [s]", "triangles", "pack_s", triangles),
        ("device buffers [MB]", "triangles", "device_mb", triangles),
        ("RSS growth while packing [MB]", "triangles", "pack_rss_mb", triangles),
        ("process peak RSS, triangle sweep [MB]", "triangles", "peak_rss_mb", triangles),
        ("RSS growth of a forward render [MB]", "pixels", "forward_rss_mb", pixels),
        ("RSS growth of a gradient pass [MB]", "pixels", "gradient_rss_mb", pixels),
    ):
        fit = _fit(fits, sweep, quantity)
        if fit is None:
            continue
        xs, ys = [r[sweep] for r in results[sweep]], [r[quantity] for r in results[sweep]]
        rows.append(
            {
                "section": "prediction",
                "what": kind,
                **where,
                "predicted": from_the_points(xs, ys, x, fit),
                "power_law": power_law_at(fit, x),
            }
        )
    return rows


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------

TABLES = {
    "triangles": (
        "Triangles: packing, memory, and time per sample at a fixed image, wall clock and process CPU "
        "(ratio = t_mitsuba / t_invrender)",
        [
            ("triangles", "triangles", "d"),
            ("build_s", "BVH build [s]", ".3f"),
            ("pack_rest_s", "rest of pack [s]", ".3f"),
            ("pack_rss_mb", "pack RSS growth [MB]", ".1f"),
            ("device_mb", "device buffers [MB]", ".1f"),
            ("peak_rss_mb", "process peak RSS [MB]", ".0f"),
            ("forward_us_per_sample", "forward [us]", ".3f"),
            ("forward_cpu_us_per_sample", "(CPU us)", ".3f"),
            ("gradient_us_per_sample", "gradient [us]", ".3f"),
            ("gradient_cpu_us_per_sample", "(CPU us)", ".3f"),
            ("mitsuba_us_per_sample", "mitsuba [us]", ".3f"),
            ("mitsuba_cpu_us_per_sample", "(CPU us)", ".3f"),
            ("ratio", "ratio", ".2f"),
            ("ratio_cpu", "ratio (CPU)", ".2f"),
            ("mitsuba_load_s", "mi load [s]", ".2f"),
            ("cpu_per_wall", "inv cpu/wall", ".2f"),
            ("load_1min", "load", ".1f"),
        ],
    ),
    "pixels": (
        "Pixels: one call's time and peak RSS growth at a fixed spp (default room)",
        [
            ("width", "W", "d"),
            ("height", "H", "d"),
            ("spp", "spp", "d"),
            ("forward_s", "forward [s]", ".4f"),
            ("forward_cpu_s", "(CPU s)", ".4f"),
            ("gradient_s", "gradient [s]", ".4f"),
            ("gradient_cpu_s", "(CPU s)", ".4f"),
            ("forward_cpu_us_per_sample", "forward [CPU us/sample]", ".3f"),
            ("gradient_cpu_us_per_sample", "gradient [CPU us/sample]", ".3f"),
            ("forward_rss_mb", "forward RSS [MB]", ".1f"),
            ("gradient_rss_mb", "gradient RSS [MB]", ".1f"),
            ("cpu_per_wall", "cpu/wall", ".2f"),
            ("load_1min", "load", ".1f"),
        ],
    ),
    "spp": (
        "Samples per pixel: one call's time and peak RSS growth at a fixed image (default room)",
        [
            ("width", "W", "d"),
            ("height", "H", "d"),
            ("spp", "spp", "d"),
            ("forward_s", "forward [s]", ".4f"),
            ("forward_cpu_s", "(CPU s)", ".4f"),
            ("gradient_s", "gradient [s]", ".4f"),
            ("gradient_cpu_s", "(CPU s)", ".4f"),
            ("forward_cpu_us_per_sample", "forward [CPU us/sample]", ".3f"),
            ("gradient_cpu_us_per_sample", "gradient [CPU us/sample]", ".3f"),
            ("forward_rss_mb", "forward RSS [MB]", ".1f"),
            ("gradient_rss_mb", "gradient RSS [MB]", ".1f"),
            ("cpu_per_wall", "cpu/wall", ".2f"),
            ("load_1min", "load", ".1f"),
        ],
    ),
    "fits": (
        "Power laws y = a x^k (Theil-Sen on log-log; k q25-q75: spread of the pairwise slopes; "
        "k top: over the three largest x)",
        [
            ("sweep", "x", "s"),
            ("quantity", "y", "s"),
            ("unit", "unit", "s"),
            ("k", "k", ".3f"),
            ("k_q25", "k q25", ".3f"),
            ("k_q75", "k q75", ".3f"),
            ("k_ls", "k (least sq.)", ".3f"),
            ("k_ls_se", "+-", ".3f"),
            ("k_top", "k top", ".3f"),
            ("a", "a", ".4g"),
            ("points", "points", "d"),
        ],
    ),
    "prediction": (
        "Prediction from the measured points (log-log between them; beyond, the top exponent), "
        "beside it the power law above",
        [
            ("what", "what", "s"),
            ("triangles", "triangles", "d"),
            ("width", "W", "d"),
            ("height", "H", "d"),
            ("spp", "spp", "d"),
            ("us_per_sample", "us/sample", ".3f"),
            ("pixel_factor", "pixel factor", ".3f"),
            ("spp_factor", "spp factor", ".3f"),
            ("predicted", "predicted", ".4g"),
            ("power_law", "(power law)", ".4g"),
            ("all_cores_wall_s", "CPU / cores [s]", ".4g"),
        ],
    ),
}
SECTIONS = ("triangles", "pixels", "spp", "fits", "prediction")


def plot_scaling(results: dict, path) -> str | None:
    """Log-log: time per sample and one-time costs against triangles, memory against triangles,
    one call's time against pixels and against spp. Returns a note if skipped."""
    plt = pyplot()
    if plt is None:
        return "matplotlib is not installed: plot skipped (the sweeps are in scaling_*.csv)"
    panels = (
        (
            "triangles",
            "triangles",
            "CPU time per sample [us]",
            ("forward_cpu_us_per_sample", "gradient_cpu_us_per_sample", "mitsuba_cpu_us_per_sample"),
        ),
        ("triangles", "triangles", "one-time [s]", ("build_s", "pack_rest_s", "mitsuba_load_s")),
        ("triangles", "triangles", "memory [MB]", ("device_mb", "pack_rss_mb", "peak_rss_mb")),
        ("pixels", "pixels", "one call [s]", ("forward_s", "forward_cpu_s", "gradient_s", "gradient_cpu_s")),
        ("spp", "spp", "one call [s]", ("forward_s", "forward_cpu_s", "gradient_s", "gradient_cpu_s")),
        ("pixels", "pixels", "peak RSS growth [MB]", ("forward_rss_mb", "gradient_rss_mb")),
    )
    fig, axes = plt.subplots(2, 3, figsize=(15, 8))
    for ax, (sweep, x, ylabel, keys) in zip(axes.ravel(), panels):
        for key in keys:
            pts = [r for r in results[sweep] if r.get(key) is not None and r[key] > 0]
            if pts:
                ax.loglog([p[x] for p in pts], [p[key] for p in pts], "o-", label=key)
        ax.set_xlabel(x)
        ax.set_ylabel(ylabel)
        ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return None


# ---------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None) -> dict:
    settings, out, variant, notes, started, load_start = start_run(
        "scaling", QUICK if quick else FULL, out, scalar_settings
    )
    if not settings.mitsuba:
        notes.append(f"Mitsuba {variant}: no peer in the triangle sweep (invrender measured alone)")
    log.info("triangle sweep ...")
    results = {"triangles": triangle_sweep(settings, variant, device)}
    log.info("pixel and spp sweeps ...")
    image = image_sweeps(settings, device)
    results["pixels"], results["spp"] = image["pixels"], image["spp"]
    results["fits"] = fit_rows(results)
    results["prediction"] = predict(results, results["fits"], settings)
    note = plot_scaling(results, out / "scaling.png")
    if note:
        notes.append(note)
    report = run_report("scaling", settings, variant, notes, started, load_start, device, results)
    report["image_sweep_triangles"] = image["triangles"]
    title = (
        f"# invrender bench scaling ({settings.mode}; Mitsuba {variant}; B = {settings.bounces}; "
        f"triangles at {settings.tri_width}x{settings.tri_height}, {settings.tri_spp} spp; "
        f"commit {report['machine'].get('git_commit', '?')}; {report['seconds']:.0f} s)"
    )
    write_report(out, "scaling", title, report, TABLES, SECTIONS)
    return report


def _main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="helpers of `invrender bench scaling`")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("triangles", help="one size of the triangle sweep; prints one JSON line")
    p.add_argument("--triangles", type=int, required=True)
    p.add_argument("--variant", help="Mitsuba's variant; none: invrender alone")
    for p in (p, sub.add_parser("image", help="the pixel and spp sweeps; prints one JSON line")):
        p.add_argument("--mode", choices=["full", "quick"], default="full")
        p.add_argument("--device")
    args = parser.parse_args(argv)
    settings = QUICK if args.mode == "quick" else FULL
    quiet_pyopencl()
    if args.command == "triangles":
        result = triangles_probe(args.triangles, settings, args.variant, args.device)
    else:
        result = image_probe(settings, args.device)
    print_probe(PROBE_MARK, result)
    return 0


if __name__ == "__main__":
    sys.exit(_main())

"""The harness every benchmark shares: clocks, seeds, memory, the Mitsuba variant, the
time-to-equal-error arithmetic, and the report (tables, CSV, JSON, plot, machine).

`bench render`, `bench gradients` and `bench export` (render.py, gradients.py, export.py) each
measure their own thing with these; docs/benchmarks.md says how they are read.
"""

from __future__ import annotations

import json
import logging
import math
import os
import platform
import subprocess
import sys
import threading
import time
from dataclasses import asdict
from pathlib import Path
from typing import NamedTuple

import numpy as np

from ..render.measure import clock, quiet_pyopencl, write_csv  # noqa: F401 - the benchmarks import them from here
from ..scene.types import SceneError

log = logging.getLogger("invrender.bench")

VARIANT_ENV = "INVRENDER_BENCH_MITSUBA_VARIANT"  # force a Mitsuba variant (e.g. scalar_rgb)
MIN_SPP_TO_JUDGE = 1000  # fewer samples per pixel: no verdict on whether two images agree


# ---------------------------------------------------------------------------------------------
# Clocks, seeds, memory
# ---------------------------------------------------------------------------------------------


def median(values) -> float:
    return float(np.median(np.asarray(values, np.float64)))


_seed_blocks = iter(range(1, 2**31, 100_003))


def next_seed_block() -> int:
    """Every runner draws its seeds from its own block, so no two renders share random numbers."""
    return next(_seed_blocks)


class PeakRSS:
    """Peak resident set size above the level at entry, polled every 2 ms by a thread
    (psutil), with getrusage's ru_maxrss growth as a floor when psutil is missing."""

    def __enter__(self):
        import resource

        self._resource = resource
        try:
            import psutil

            self._process = psutil.Process()
        except ImportError:
            self._process = None
        self.start = self._rss()
        self.peak = self.start
        self._maxrss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
        self._stop = threading.Event()
        if self._process is not None:
            self._thread = threading.Thread(target=self._poll, daemon=True)
            self._thread.start()
        return self

    def _rss(self) -> int:
        if self._process is not None:
            return int(self._process.memory_info().rss)
        return self._resource.getrusage(self._resource.RUSAGE_SELF).ru_maxrss * 1024

    def _poll(self):
        while not self._stop.wait(0.002):
            self.peak = max(self.peak, self._rss())

    def __exit__(self, *exc):
        self._stop.set()
        if self._process is not None:
            self._thread.join()
        self.peak = max(self.peak, self._rss())
        maxrss = self._resource.getrusage(self._resource.RUSAGE_SELF).ru_maxrss * 1024
        self.growth = max(self.peak - self.start, maxrss - self._maxrss0)
        return False


def measure(fn, *args, **kwargs) -> tuple[object, dict]:
    """(result, or the SceneError it stopped with; {wall_s, cpu_s, peak_rss_mb, rss_growth_mb})
    of one call in this process."""
    wall, cpu = time.perf_counter(), time.process_time()
    with PeakRSS() as memory:
        try:
            out = fn(*args, **kwargs)
        except SceneError as stop:
            out = stop
    return out, {
        "wall_s": time.perf_counter() - wall,
        "cpu_s": time.process_time() - cpu,
        "peak_rss_mb": memory.peak / 2**20,
        "rss_growth_mb": memory.growth / 2**20,
    }


class Stopped(Exception):
    """A step stopped with a SceneError, now or in an earlier run (its message in steps.json)."""


class Ledger:
    """steps.json in a folder: each step's measurements, written as soon as it ran, so that a
    resumed run reports the times of the steps it skips. A step that stopped with a SceneError
    is a result too (bench duplicates' ablation that registers nothing): its time and message are kept, and a
    resumed run reports it again without running it (delete its entry to retry)."""

    def __init__(self, folder: Path):
        self.path = Path(folder) / "steps.json"
        self.steps = json.loads(self.path.read_text()) if self.path.exists() else {}

    def run(self, step: str, output: Path, fn, *args, **kwargs) -> dict | None:
        if Path(output).exists():
            log.info("bench: %s exists, %s skipped", output, step)
            return self.steps.get(step)
        if (self.steps.get(step) or {}).get("error"):
            raise Stopped(self.steps[step]["error"])
        out, measured = measure(fn, *args, **kwargs)
        if isinstance(out, SceneError):
            measured["error"] = str(out)
        self._write(step, measured)
        if isinstance(out, SceneError):
            raise Stopped(str(out)) from out
        return measured

    def _write(self, step: str, measured: dict):
        self.steps[step] = measured
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.path.write_text(json.dumps(self.steps, indent=1) + "\n")


def run_probe(module: str, args, mark: str, what: str, env: dict | None = None) -> dict:
    """Run `python -m module args` in its own process (so that its peak memory is its own) and
    return the JSON it printed after `mark` (`print_probe`); its stderr in the error if it failed."""
    command = [sys.executable, "-m", module, *map(str, args)]
    proc = subprocess.run(command, capture_output=True, text=True, env={**os.environ, **(env or {})})
    lines = [line for line in proc.stdout.splitlines() if line.startswith(mark)]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"{what} failed with code {proc.returncode}:\n{proc.stderr[-4000:]}")
    return json.loads(lines[-1][len(mark) :])


def print_probe(mark: str, result: dict):
    print(mark + json.dumps(result), flush=True)


def scene_buffer_bytes(host) -> tuple[int, int]:
    """(all device buffers, the geometry's: triangles and BVH) of a HostScene, in bytes."""
    from ..render.scene_buffers import GEOMETRY_ARGS, SCENE_ARGS

    arrays = {arg.name: getattr(host, arg.name) for arg in SCENE_ARGS if arg.buffer}
    return sum(a.nbytes for a in arrays.values()), sum(arrays[k].nbytes for k in GEOMETRY_ARGS)


# ---------------------------------------------------------------------------------------------
# What is compared
# ---------------------------------------------------------------------------------------------


def room_scene(width: int | None = None, height: int | None = None, config: dict | None = None):
    """The synthetic room (``synthesize.room``) and its metadata; its cameras width x height if
    given, else the room's default cameras (96 x 72)."""
    from ..synthesize.room import make_room

    config = dict(config or {})
    if width:
        config["cameras"] = {"width": int(width), "height": int(height)}
    return make_room(config)


def choose_variant() -> tuple[str, str | None]:
    """The Mitsuba variant to compare against and, if it is not llvm_ad_rgb, why."""
    from .. import mitsuba as bridge  # noqa: I001 - first: it points drjit at a usable libLLVM
    import mitsuba as mi

    forced = os.environ.get(VARIANT_ENV)
    if forced:
        note = None if forced == "llvm_ad_rgb" else f"Mitsuba variant forced to {forced} by ${VARIANT_ENV}"
        return forced, note
    if bridge.DEFAULT_VARIANT == "llvm_ad_rgb" and "llvm_ad_rgb" in mi.variants():
        return "llvm_ad_rgb", None
    return "scalar_rgb", (
        "Mitsuba's llvm_ad_rgb variant is unavailable (no libLLVM >= 16 found; Debian: apt-get install "
        "libllvm19, or set DRJIT_LIBLLVM_PATH). Comparing against scalar_rgb instead, a much weaker peer "
        "(one lane, the Python milo BSDF called per sample), at a reduced image size and ladder."
    )


class RunStart(NamedTuple):
    """What every benchmark run starts from (`start_run`)."""

    settings: object
    out: Path
    variant: str
    notes: list
    started: float
    load_start: tuple


def start_run(name: str, settings, out, scalar_settings) -> RunStart:
    """The start every benchmark shares: pyopencl quiet, the output folder made, the Mitsuba
    variant chosen (settings scaled down by `scalar_settings` for anything but llvm_ad_rgb, and
    why in the notes), the wall clock and the load average noted."""
    quiet_pyopencl()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    notes = []
    variant, why = choose_variant()
    if variant != "llvm_ad_rgb":
        settings = scalar_settings(settings)
        notes.append(why)
        log.warning("%s", why)
    log.info("bench %s (%s): Mitsuba %s, out %s", name, settings.mode, variant, out)
    return RunStart(settings, out, variant, notes, time.time(), os.getloadavg())


# ---------------------------------------------------------------------------------------------
# Time to equal error
# ---------------------------------------------------------------------------------------------


def time_at_rmse(times, rmses, target) -> tuple[float, bool]:
    """Time at which a (time, RMSE) ladder reaches `target`: log-log interpolation between the
    bracketing rungs; c / sqrt(t) extrapolation from the nearest end (flag True) outside."""
    t = np.maximum.accumulate(np.asarray(times, np.float64))
    r = np.minimum.accumulate(np.asarray(rmses, np.float64))
    if target < r[-1]:
        return float(t[-1] * (r[-1] / target) ** 2), True
    if target >= r[0]:
        return float(t[0] * (r[0] / target) ** 2), target > r[0]
    k = int(np.nonzero(r <= target)[0][0])  # first rung at or below the target; k >= 1
    r0, r1, t0, t1 = r[k - 1], r[k], t[k - 1], t[k]
    if r0 == r1:
        return float(t1), False
    s = (math.log(r0) - math.log(target)) / (math.log(r0) - math.log(r1))
    return float(math.exp(math.log(t0) + s * (math.log(t1) - math.log(t0)))), False


def pairwise_slopes(x, y) -> np.ndarray:
    """(y_j - y_i) / (x_j - x_i) over every pair i < j with x_i != x_j: their median is the
    Theil-Sen slope, which one point timed during a burst of load does not move."""
    x, y = np.asarray(x, np.float64), np.asarray(y, np.float64)
    i, j = np.triu_indices(len(x), 1)
    keep = x[j] != x[i]
    return (y[j] - y[i])[keep] / (x[j] - x[i])[keep]


def fit_model(spps, times, rmses) -> dict:
    """RMSE = k / sqrt(spp) and t = a + b spp, i.e. RMSE = k sqrt(b) / sqrt(t - a): the
    c / sqrt(t) law with a fixed per-call cost a. k = median of rmse sqrt(spp) over the upper
    half of the ladder; (a, b) by Theil-Sen (median of pairwise slopes), so one rung timed
    during a burst of load from other processes does not move the fit."""
    spps, times, rmses = (np.asarray(v, np.float64) for v in (spps, times, rmses))
    half = len(spps) // 2
    k = median(rmses[half:] * np.sqrt(spps[half:]))
    b = max(median(pairwise_slopes(spps, times)), 1e-30)
    a = median(times - b * spps)
    return {"k": k, "a": a, "b": b}


def model_time(model: dict, target: float) -> float:
    return max(model["a"], 0.0) + model["b"] * (model["k"] / target) ** 2


def verdict(check: dict, spp: int, tolerance: float = 0.01) -> str:
    """ "agree" (|mean rel diff| <= tolerance), "DIFFER" (beyond it by more than 3 sigma of the
    noise: a bug to report, not noise) or "unresolved" (beyond it, but within the noise);
    "not checked" below MIN_SPP_TO_JUDGE samples per pixel, where the sun's rare bright paths
    are missing from the sample and its noise estimate is not to be trusted (quick runs)."""
    diff, sigma = abs(check["mean_rel_diff"]), check["mean_rel_sigma"]
    if spp < MIN_SPP_TO_JUDGE:
        return "not checked"
    if diff <= tolerance:
        return "agree"
    return "DIFFER" if diff - tolerance > 3 * sigma else "unresolved"


# ---------------------------------------------------------------------------------------------
# The report
# ---------------------------------------------------------------------------------------------


def _cell(value, fmt: str) -> str:
    if value is None or (isinstance(value, float) and not math.isfinite(value)):
        return "-" if value is None else str(value)
    if fmt.endswith("%"):
        return format(float(value), fmt)
    if fmt == "d":
        return str(int(value))
    if fmt == "s":
        return str(value)
    return format(float(value), fmt)


def format_table(title: str, columns, rows) -> str:
    cells = [[header for _, header, _ in columns]]
    cells += [[_cell(row.get(key), fmt) for key, _, fmt in columns] for row in rows]
    widths = [max(len(r[k]) for r in cells) for k in range(len(columns))]
    line = lambda r: "| " + " | ".join(c.ljust(w) for c, w in zip(r, widths)) + " |"
    sep = "|" + "|".join("-" * (w + 2) for w in widths) + "|"
    return "\n".join([f"### {title}", "", line(cells[0]), sep] + [line(r) for r in cells[1:]]) + "\n"


def pyplot():
    """matplotlib.pyplot drawing to files, or None: matplotlib is optional (plots are skipped)."""
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return None
    return plt


def plot(
    curves: list[dict],
    equal: list[dict],
    path: Path,
    xlabel: str = "wall time per image [s]",
    ylabel: str = "RMSE vs reference",
    curves_csv: str = "render_curves.csv",
) -> str | None:
    """RMSE against time, log-log, one panel per bounce count. Returns a note if skipped.
    Rows: curves with bounces, renderer, wall_s, rmse; equal with bounces, target_rmse."""
    plt = pyplot()
    if plt is None:
        return f"matplotlib is not installed: plot skipped (the curves are in {curves_csv})"
    bounces = sorted({c["bounces"] for c in curves})
    fig, axes = plt.subplots(1, len(bounces), figsize=(5 * len(bounces), 4), squeeze=False)
    for ax, b in zip(axes[0], bounces):
        names = sorted({c["renderer"] for c in curves if c["bounces"] == b}, key=lambda n: (n == "mitsuba", n))
        for name, style in zip(names, ("o-", "^-.", "v:", "d-")):
            style = "s--" if name == "mitsuba" else style
            pts = [c for c in curves if c["bounces"] == b and c["renderer"] == name]
            ax.loglog([p["wall_s"] for p in pts], [p["rmse"] for p in pts], style, label=name)
        target = [e for e in equal if e["bounces"] == b][0]["target_rmse"]
        ax.axhline(target, color="grey", lw=0.8, ls=":")
        ax.set_title(f"{b} bounces")
        ax.set_xlabel(xlabel)
        ax.set_ylabel(ylabel)
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return None


def run_report(
    name: str, settings, variant: str, notes: list, started: float, load_start: tuple, device, results: dict, **extra
) -> dict:
    """The report every benchmark writes: what ran, on which machine (with the load average at
    the start and the end, since these machines are shared), how long, the notes, the results."""
    machine = machine_info(device)
    machine["load_average_start"] = load_start
    machine["load_average_end"] = os.getloadavg()
    return {
        "benchmark": name,
        "mode": settings.mode,
        "mitsuba_variant": variant,
        **extra,
        "settings": asdict(settings),
        "machine": machine,
        "seconds": time.time() - started,
        "notes": notes,
        **results,
    }


def machine_info(device=None) -> dict:
    info = {"python": platform.python_version(), "platform": platform.platform(), "cpus": os.cpu_count()}
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                info["cpu"] = line.split(":", 1)[1].strip()
                break
        info["memory_gb"] = round(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**30, 1)
    except (OSError, ValueError):
        pass
    try:
        from ..render.device import choose_device, describe

        info["opencl_device"] = describe(choose_device(device))
    except Exception as error:  # noqa: BLE001 - informational only
        info["opencl_device"] = f"unknown ({error})"
    try:
        import drjit
        import mitsuba

        info["mitsuba"], info["drjit"] = mitsuba.__version__, drjit.__version__
        info["DRJIT_LIBLLVM_PATH"] = os.environ.get("DRJIT_LIBLLVM_PATH")
    except ImportError:
        pass
    info["numpy"] = np.__version__
    try:
        root = Path(__file__).resolve().parents[3]
        info["git_commit"] = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "--short", "HEAD"], capture_output=True, text=True
        ).stdout.strip()
    except OSError:
        pass
    return info


def write_report(out: Path, name: str, title: str, report: dict, tables: dict, sections) -> str:
    """Write `name`.json (the report), one CSV per section, `name`_table.md (the title, a table
    per section, the machine, the notes) under `out`; print the tables and return them.
    tables: section -> (title, [(key, header, format), ...]), as `format_table` takes."""
    text = [title, ""] + [format_table(*tables[key], report[key]) for key in sections]
    text.append("Machine: " + ", ".join(f"{k}={v}" for k, v in report["machine"].items()))
    text += [f"NOTE: {n}" for n in report["notes"]]
    table = "\n".join(text) + "\n"
    (out / f"{name}.json").write_text(json.dumps(report, indent=1, default=float, allow_nan=False) + "\n")
    for key in sections:
        write_csv(out / f"{name}_{key}.csv", report[key])
    (out / f"{name}_table.md").write_text(table)
    sys.stdout.write(table)
    sys.stdout.flush()
    return table


def portable(value, roots: dict[str, str]):
    """``value`` (a report: dicts, lists, strings) with every folder of ``roots`` written as its
    placeholder ({work folder: "WORK"}: the work folder's "living" subfolder -> "WORK/living"), so
    that a committed report names no folder of the machine it ran on."""
    if isinstance(value, dict):
        return {key: portable(v, roots) for key, v in value.items()}
    if isinstance(value, list):
        return [portable(v, roots) for v in value]
    if isinstance(value, str):
        for folder in sorted(roots, key=len, reverse=True):
            value = value.replace(folder, roots[folder])
    return value


def run_scenes(
    name: str, settings, out: Path, run_one, table_row, write_markdown, quick_note: str, device, start, roots=None
):
    """The scene loop of the per-scene benchmarks (bench duplicates, bench duplicates-material,
    bench room): `run_one(scene) -> rows` for each of `settings.scenes`, the report (OUT/<name>.json,
    and the markdown `write_markdown(out, report)` writes) rewritten after every scene so that
    partial runs count, then printed. `start`: (time.time(), os.getloadavg()) when the benchmark
    began. Folders in the report are written as placeholders (``portable``): the work folder as
    WORK, and ``roots`` ({folder: placeholder}) besides."""
    stem = name.replace("-", "_")
    rows = []
    work = Path(settings.work)
    roots = {str(work.resolve()): "WORK", str(work): "WORK", **(roots or {})}

    def write() -> dict:
        notes = [f"quick: {quick_note}"] if settings.mode == "quick" else []
        results = {"work": "WORK", "rows": rows, "table": [table_row(row) for row in rows]}
        report = portable(run_report(name, settings, "not used", notes, *start, device, results), roots)
        (out / f"{stem}.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
        write_markdown(out, report)
        return report

    for scene in settings.scenes:
        rows += run_one(scene)
        write()
    report = write()
    sys.stdout.write((out / f"{stem}.md").read_text())
    sys.stdout.flush()
    return report


GEOMETRY_KEYS = (
    "target_faces",
    "texels_per_meter",
    "atlas_resolution",
    "padding",
    "poisson_depth",
    "min_island_fraction",
    "min_island_faces",
)


def capture_geometry(work: Path, config: dict, progress: bool = False) -> None:
    """The geometry stage on WORK/capture/mesh.ply into WORK/geometry, with a workflow config's
    `geometry:` settings, as the rule calls it."""
    from ..geometry import stage as geometry

    settings = {key: config["geometry"][key] for key in GEOMETRY_KEYS}
    geometry.run(work / "capture" / "mesh.ply", work / "geometry", progress=progress, **settings)

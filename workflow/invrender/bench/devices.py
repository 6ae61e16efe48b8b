"""`invrender devices`: every OpenCL platform and device, whether it builds the kernels, its
throughput on a small scene, and which one a run would choose and why.

The throughput is path samples per second of the demo room (view 2: glossy table, window, sky) at
3 bounces, after a warm-up render that builds the kernel, median of three renders: a quick
comparison of the devices, not a benchmark (`invrender bench render` is that).
"""

from __future__ import annotations

import logging
import time
from dataclasses import dataclass

from ..render.device import DeviceError, all_devices, candidates, describe, explain_choice, kernel_check, rank

log = logging.getLogger("invrender.devices")

SPP = 32
REPEATS = 3
BOUNCES = 3
VIEW = 2


@dataclass
class Row:
    name: str  # "platform / device", what `device:` matches
    kind: str  # CPU, GPU, ...
    version: str  # the driver's OpenCL version and build
    error: str | None  # None: builds the kernels
    samples_per_second: float | None = None
    chosen: bool = False


def _kind(device) -> str:
    import pyopencl as cl

    kinds = [name for name in ("GPU", "CPU", "ACCELERATOR") if device.type & getattr(cl.device_type, name)]
    return kinds[0] if kinds else "other"


def throughput(device_name: str) -> float:
    """Path samples per second of the demo room on the device `device_name` names."""
    from ..render.features import Features
    from ..render.renderer import Renderer
    from .harness import room_scene

    scene, _ = room_scene()
    camera = scene.cameras[VIEW]
    renderer = Renderer(scene, Features(max_bounces=BOUNCES), device=device_name)
    renderer.render(camera, spp=1, aovs=False)  # builds and loads the kernel
    times = []
    for seed in range(REPEATS):
        start = time.perf_counter()
        renderer.render(camera, spp=SPP, seed=seed, aovs=False)
        times.append(time.perf_counter() - start)
    return camera.width * camera.height * SPP / sorted(times)[len(times) // 2]


def survey(name: str | None = None, measure: bool = True) -> tuple[list[Row], str]:
    """One row per device in the automatic choice's order, and the sentence that says which
    device a run (with `device: name`) would use and why."""
    candidates(name)  # a name that matches nothing is refused before any build
    devices = sorted(all_devices(), key=rank)
    rows = [
        Row(describe(d), _kind(d), f"{' '.join(d.version.split()[:2])}, driver {d.driver_version}", kernel_check(d))
        for d in devices
    ]
    for row in rows:
        if measure and row.error is None:
            row.samples_per_second = throughput(row.name)
    try:
        choice = explain_choice(name)
    except DeviceError as error:
        return rows, str(error)
    chosen = describe(choice.device)
    for row in rows:
        row.chosen = row.name == chosen
    skipped = "".join(f"; skipped {describe(d)}, which cannot build the kernels" for d, _ in choice.skipped)
    return rows, f"a run uses {chosen}: {choice.why}{skipped}"


def table(rows: list[Row]) -> str:
    header = ["", "device (platform / device)", "kind", "OpenCL", "builds the kernels", "samples/s"]
    body = [
        [
            "*" if row.chosen else "",
            row.name,
            row.kind,
            row.version,
            "yes" if row.error is None else f"no: {row.error}",
            "" if row.samples_per_second is None else f"{row.samples_per_second / 1e3:,.0f} k",
        ]
        for row in rows
    ]
    widths = [max(len(line[i]) for line in [header, *body]) for i in range(len(header))]
    return "\n".join("  ".join(cell.ljust(w) for cell, w in zip(line, widths)).rstrip() for line in [header, *body])


def run(name: str | None = None, measure: bool = True) -> list[Row]:
    """Print the survey; a DeviceError (exit 2) when no device would do."""
    rows, verdict = survey(name, measure)
    print(table(rows))
    print(f"\n{verdict}")
    if not any(row.chosen for row in rows):
        raise DeviceError(verdict)
    return rows

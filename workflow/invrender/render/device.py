"""OpenCL device choice: a device that builds the kernels, named by the config or else the
fastest kind this machine has.

Without a name, candidates come in this order: GPUs, then the CPU runtimes in the order that
`invrender bench render` measured (CPU_RUNTIMES, docs/benchmarks.md "CPU OpenCL runtimes"), then
anything else. Each candidate is checked by building the real entry kernels with every effect
compiled in (render.cl, adjoint.cl, silhouette.cl), once per device, driver and kernel source
(the verdict is cached on disk), and a device that cannot build them is skipped with one line
naming it and its compiler's message: PyPI's PoCL 3.0 bundles an LLVM that does not know the
newest CPUs ("unknown target CPU 'generic'"), and a run must not die at its first job for it.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import re
from dataclasses import dataclass
from functools import cache

import pyopencl as cl

from .cache import cache_root
from .program import assemble_source, build

log = logging.getLogger("invrender.render.device")

# CPU runtimes, fastest first (docs/benchmarks.md, "CPU OpenCL runtimes"): a substring of the
# platform name, and for PoCL the newer build before the older, whose LLVM knows fewer CPUs.
CPU_RUNTIMES = ("Intel(R) OpenCL", "Portable Computing Language")
INSTALL_HINT = (
    "install a CPU OpenCL runtime: `pip install intel-opencl-rt intel-cmplr-lib-rt` (Intel's, for "
    "any x86-64 CPU) or, as root, `apt-get install pocl-opencl-icd` (Debian's PoCL)"
)
# Environment variables through which the runtimes take compiler settings: part of a verdict's key.
COMPILER_ENV = ("POCL_EXTRA_BUILD_FLAGS", "CL_CONFIG_CPU_TARGET_ARCH", "OCL_ICD_VENDORS")


class DeviceError(RuntimeError):
    pass


def all_devices() -> list[cl.Device]:
    try:
        platforms = cl.get_platforms()
    except cl.Error as error:  # no ICD at all
        raise DeviceError(f"device: no OpenCL platform found ({error}); {INSTALL_HINT}") from error
    return [device for platform in platforms for device in platform.get_devices()]


def describe(device: cl.Device) -> str:
    return f"{device.platform.name.strip()} / {device.name.strip()}"


def rank(device: cl.Device) -> tuple:
    """Sort key of the automatic choice: GPUs, then CPU_RUNTIMES in order, newer versions first."""
    platform = device.platform.name
    runtime = next((i for i, name in enumerate(CPU_RUNTIMES) if name in platform), len(CPU_RUNTIMES))
    version = tuple(int(n) for n in re.findall(r"\d+", device.platform.version)[2:4])  # "OpenCL 3.0 PoCL 3.1"
    is_gpu = bool(device.type & cl.device_type.GPU)
    return (not is_gpu, runtime, tuple(-n for n in version))


def entry_kernels(device: cl.Device) -> list[tuple[str, tuple[str, ...]]]:
    """The entry kernels a run builds, each with every effect compiled in, as built on `device`."""
    from .adjoint import LAYOUT_DEFINES, NUM_BUCKETS, accumulation_defines, choose_accumulation
    from .features import Features

    everything = Features.everything().defines()
    buckets = None if choose_accumulation(device, "auto") == "fixed" else NUM_BUCKETS
    adjoint = everything + LAYOUT_DEFINES + accumulation_defines(buckets)
    return [("render.cl", everything), ("adjoint.cl", adjoint), ("silhouette.cl", ())]


def compiler_message(error: Exception) -> str:
    """One line of what the runtime said: its status, and the build log's first error line."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    if not lines:
        return type(error).__name__
    head = lines[0].split(" - ")[0]
    detail = next((line for line in lines[1:] if re.search(r"error|invalid|unknown|not supported", line, re.I)), None)
    return f"{head}: {detail}" if detail else head


def _build_entry_kernels(device: cl.Device) -> str | None:
    try:
        context = cl.Context([device])
        for entry, options in entry_kernels(device):
            build(cl.Program(context, assemble_source(entry)), options)
    except cl.Error as error:
        return compiler_message(error)
    return None


def _verdict_path(device: cl.Device):
    identity = [describe(device), device.driver_version, device.platform.version, cl.VERSION_TEXT]
    identity += [f"{name}={os.environ.get(name, '')}" for name in COMPILER_ENV]
    identity += [assemble_source(entry) + " ".join(options) for entry, options in entry_kernels(device)]
    key = hashlib.sha256("\n".join(identity).encode()).hexdigest()
    return cache_root() / "device-checks" / f"{key}.json"


def kernel_check(device: cl.Device) -> str | None:
    """None if `device` builds the entry kernels, else the compiler's message (cached on disk)."""
    path = _verdict_path(device)
    if path.is_file():
        return json.loads(path.read_text())["error"]
    log.info("device: checking that %s builds the kernels (once per device and kernel version)", describe(device))
    error = _build_entry_kernels(device)
    path.parent.mkdir(parents=True, exist_ok=True)
    temporary = path.with_suffix(f".tmp{os.getpid()}")
    temporary.write_text(json.dumps({"device": describe(device), "error": error}))
    temporary.replace(path)
    return error


@dataclass(frozen=True)
class Choice:
    device: cl.Device
    why: str
    skipped: tuple[tuple[cl.Device, str], ...]  # (device, compiler message) passed over


def candidates(name: str | None) -> tuple[list[cl.Device], str]:
    """The devices a choice considers, in order, and what put them in that order."""
    devices = all_devices()
    if name:
        exact = [d for d in devices if describe(d).lower() == name.lower()]
        matches = exact or sorted((d for d in devices if name.lower() in describe(d).lower()), key=rank)
        if not matches:
            listing = "; ".join(describe(d) for d in devices) or "none"
            raise DeviceError(f"device: no OpenCL device matches {name!r}; available: {listing}")
        return matches, f"its name contains {name!r}"
    if not devices:
        raise DeviceError(f"device: no OpenCL device found; {INSTALL_HINT}")
    return sorted(devices, key=rank), "the fastest kind here (GPUs, then the CPU runtimes in measured order)"


def explain_choice(name: str | None = None) -> Choice:
    """The device `name` (or $INVRENDER_DEVICE, a case-insensitive substring of 'platform /
    device') picks, else the first candidate in rank order, that builds the kernels."""
    name = name or os.environ.get("INVRENDER_DEVICE") or None
    ordered, why = candidates(name)
    skipped = []
    for device in ordered:
        error = kernel_check(device)
        if error is None:
            return Choice(device, why, tuple(skipped))
        skipped.append((device, error))
    reasons = "; ".join(f"{describe(d)}: {error}" for d, error in skipped)
    which = f"matching {name!r}" if name else "here"
    raise DeviceError(f"device: no OpenCL device {which} builds the kernels ({reasons}); {INSTALL_HINT}")


def choose_device(name: str | None = None) -> cl.Device:
    """The device a run uses (`name`, else $INVRENDER_DEVICE, else the automatic choice)."""
    return _choose(name or os.environ.get("INVRENDER_DEVICE") or None)


@cache
def _choose(name: str | None) -> cl.Device:
    """One choice per process and name, with one warning line per device that was skipped."""
    choice = explain_choice(name)
    for device, error in choice.skipped:
        log.warning("device: skipping %s: it cannot build the kernels (%s)", describe(device), error)
    return choice.device


def context_and_queue(name: str | None = None) -> tuple[cl.Context, cl.CommandQueue]:
    """One context and in-order queue per device, shared by every renderer in the process."""
    return _context_and_queue(choose_device(name))


@cache
def _context_and_queue(device: cl.Device) -> tuple[cl.Context, cl.CommandQueue]:
    context = cl.Context([device])
    return context, cl.CommandQueue(context)

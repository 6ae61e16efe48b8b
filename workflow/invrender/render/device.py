"""OpenCL device choice: a name substring from the config, else a GPU if there is one, else PoCL."""

from __future__ import annotations

import os
from functools import cache

import pyopencl as cl


class DeviceError(RuntimeError):
    pass


def all_devices() -> list[cl.Device]:
    try:
        platforms = cl.get_platforms()
    except cl.Error as error:  # no ICD at all
        raise DeviceError(f"no OpenCL platform found ({error}); install pocl-binary-distribution") from error
    return [device for platform in platforms for device in platform.get_devices()]


def describe(device: cl.Device) -> str:
    return f"{device.platform.name.strip()} / {device.name.strip()}"


def choose_device(name: str | None = None) -> cl.Device:
    """`name` (or $INVRENDER_DEVICE) is a case-insensitive substring of 'platform / device'."""
    name = name or os.environ.get("INVRENDER_DEVICE") or None
    devices = all_devices()
    if name:
        matches = [d for d in devices if name.lower() in describe(d).lower()]
        if not matches:
            listing = "; ".join(describe(d) for d in devices) or "none"
            raise DeviceError(f"device: no OpenCL device matches {name!r}; available: {listing}")
        return matches[0]
    gpus = [d for d in devices if d.type & cl.device_type.GPU]
    if gpus:
        return gpus[0]
    if not devices:
        raise DeviceError("device: no OpenCL device found; install pocl-binary-distribution")
    return devices[0]


@cache
def context_and_queue(name: str | None = None) -> tuple[cl.Context, cl.CommandQueue]:
    """One context and in-order queue per device, shared by every renderer in the process."""
    device = choose_device(name)
    context = cl.Context([device])
    return context, cl.CommandQueue(context)

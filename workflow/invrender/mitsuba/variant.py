"""The Mitsuba variant the tests and benchmarks render with, and the plugins registered for it.

`llvm_ad_rgb` when drjit has a usable libLLVM (llvm.py): vectorised, ~70x faster with the Python
plugins, and differentiable (prb). Otherwise `scalar_rgb`, which works everywhere but calls the
Python plugins once per sample with Python floats.
"""

from __future__ import annotations

import mitsuba as mi

from . import camera, milo, usd_preview
from .llvm import llvm_available

DEFAULT_VARIANT = "llvm_ad_rgb" if llvm_available() else "scalar_rgb"

_registered: dict[str, dict] = {}  # variant -> plugin name -> class


def set_variant(variant: str = DEFAULT_VARIANT) -> None:
    """Select a Mitsuba variant and register this package's plugins for it (idempotent)."""
    if mi.variant() != variant:
        mi.set_variant(variant)
    if variant not in _registered:
        milo_class = milo.make_class()
        classes = {
            "milo": milo_class,
            "invrender_camera": camera.make_class(),
            "usd_preview_lobe": usd_preview.make_class(milo_class),
        }
        for name, cls in classes.items():
            register = mi.register_sensor if issubclass(cls, mi.Sensor) else mi.register_bsdf
            register(name, lambda props, cls=cls: cls(props))
        _registered[variant] = classes

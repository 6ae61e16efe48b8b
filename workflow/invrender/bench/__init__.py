"""Benchmarks: `invrender bench WHAT`, each comparing invrender with a peer in the same run.

- ``render``: the forward renderer against Mitsuba 3 (``render.py``; docs/benchmarks.md).
- ``gradients``: one gradient pass against Mitsuba 3's ``prb`` (``gradients.py``; docs/benchmarks.md).
- ``blender``: Blender's Cycles against ours on the room's USD export, variant by variant
  (``python -m invrender.bench.blender``; its Blender side is ``blender_client.py``, run in
  Blender's own interpreter; docs/export.md, "Blender").

Submodules are imported when run, so ``python -m invrender.bench.render`` (the helper
subprocess of the BVH measurement) does not find its module already imported.
"""

from __future__ import annotations

BENCHMARKS = ("render", "gradients")


def run_benchmark(what: str, args) -> dict:
    """Run benchmark ``what`` with the CLI's namespace (quick, out, device); returns its results."""
    if what == "render":
        from .render import run

        return run(quick=bool(getattr(args, "quick", False)), out=getattr(args, "out", "docs/benchmarks"),
                   device=getattr(args, "device", None))
    if what == "gradients":
        from .gradients import run

        return run(quick=bool(getattr(args, "quick", False)), out=getattr(args, "out", "docs/benchmarks"),
                   device=getattr(args, "device", None))
    raise ValueError(f"bench: expected one of {list(BENCHMARKS)}, got {what!r}")

"""Benchmarks: `invrender bench WHAT`, each comparing invrender with a peer in the same run.

- ``render``: the forward renderer against Mitsuba 3 (``render.py``; docs/benchmarks.md).
- ``gradients``: one gradient pass against Mitsuba 3's ``prb`` (``gradients.py``; docs/benchmarks.md).
- ``blender``: Blender's Cycles against ours on the room's USD export, variant by variant
  (``python -m invrender.bench.blender``; its Blender side is ``blender_client.py``, run in
  Blender's own interpreter; docs/export.md, "Blender").
- ``export``: what the USD export loses: round trip, standard view, GGX in Mitsuba 3 (``export.py``;
  docs/export.md).
- ``scaling``: time and memory against triangles (1 k to 1 M), pixels and spp, with fitted
  exponents and a worked prediction; Mitsuba 3 beside the triangle sweep (``scaling.py``;
  docs/benchmarks.md, "Scaling").
- ``traversal``: closest-hit throughput of the BVH alone, on the room and the room at ~214 k
  triangles, beside a B = 1 render of ours and Mitsuba's (``traversal.py``; docs/benchmarks.md).
- ``milo``: MILO recovery on rooms Mitsuba 3 rendered, against the per-texel and constant guesses
  and the truth on our atlas, on a tuning and a held-out split (``milo_independent.py``); and on
  the benchmark room (config/benchmark.yaml) beside the paper's Table 3, with the Fig. 12
  ablation (``milo.py``; docs/benchmarks.md, docs/milo.md).
- ``accuracy``: the accuracy stage's full sweep on the demo's scenes through the workflow, the
  recovery sweep's training runs included (``accuracy.py``; docs/accuracy.md).
- ``duplicates``: Structure from Duplicates on the synthetic fixtures beside the paper's Table 2,
  with the rotation-search and SIFT ablations (``duplicates.py``; docs/benchmarks.md).
- ``duplicates-material``: the shared material and sky of the duplicates fixtures, with true and
  recovered poses, beside the paper's Tables 1 and 2 (``duplicates_material.py``; docs/benchmarks.md).

- ``room``: the room mode (PSDR-Room) on the three synthetic layouts through the room stages,
  a table per result: box, objects, masks, photo, light and material, time (``room.py``;
  docs/benchmarks.md, "Room").
- ``summary``: not a measurement: the README's table of headline results, rewritten from the JSON
  files the benchmarks above left under ``--out`` (``summary.py``; tests/bench/test_bench_summary.py
  keeps the two equal).

``harness.py`` is what they share (clocks, seeds, memory, the Mitsuba variant, the report).
Submodules are imported when run, so ``python -m invrender.bench.render`` (the helper
subprocess of the BVH measurement) does not find its module already imported.
"""

from __future__ import annotations

import importlib

# modules here: run(quick, out, device)
BENCHMARKS = (
    "render",
    "gradients",
    "export",
    "milo",
    "scaling",
    "traversal",
    "duplicates",
    "duplicates-material",
    "accuracy",
    "room",
    "summary",
)
OPTIONS = {
    "milo": ("config", "iterations", "ablation", "work", "sections"),
    "render": ("sections",),
    "duplicates": ("scenes", "variants", "work"),
    "duplicates-material": ("scenes", "poses", "variants", "work"),
    "accuracy": ("work",),
    "room": ("scenes", "work"),
    "summary": ("readme",),
}  # what only some take


def run_benchmark(what: str, args) -> dict:
    """Run benchmark ``what`` with the CLI's namespace (quick, out, device, and the options that
    benchmark takes, OPTIONS); returns its results. An option given to a benchmark that does not
    take it is refused."""
    from ..scene.types import SceneError

    if what not in BENCHMARKS:
        raise ValueError(f"bench: expected one of {list(BENCHMARKS)}, got {what!r}")
    given = {
        key: getattr(args, key) for keys in OPTIONS.values() for key in keys if getattr(args, key, None) is not None
    }
    stray = sorted(set(given) - set(OPTIONS.get(what, ())))
    if stray:
        owners = {key: name for name, keys in OPTIONS.items() for key in keys}
        raise SceneError(
            f"bench {what}", ", ".join(f"--{key}" for key in stray), f"options of bench {owners[stray[0]]} only"
        )
    run = importlib.import_module(f".{what.replace('-', '_')}", __name__).run
    return run(
        quick=bool(getattr(args, "quick", False)),
        out=getattr(args, "out", "docs/benchmarks"),
        device=getattr(args, "device", None),
        **given,
    )

"""Measures retrieval, the transform search and the fit on synthetic crops (docs/materials.md):

PYTHONPATH=workflow python tests/materials/measure.py [crops per preset] [fit steps] [seed]
"""

from __future__ import annotations

import math
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).parent))
from crops import rotation_error, synthetic_crop  # noqa: E402

from invrender.materials import PRESETS  # noqa: E402
from invrender.materials.base import mean_albedo  # noqa: E402
from invrender.materials.fit import fit  # noqa: E402
from invrender.materials.retrieval import retrieve  # noqa: E402

# Degrees after which each pattern repeats (None: isotropic or flat, its rotation is moot).
SYMMETRY = {"plain": None, "noise": None, "checker": 90.0, "tiles": 180.0, "wood": 180.0, "fabric": 180.0}


def parameter_error(material, params, truth) -> float:
    """Mean |difference| of the texture parameters in units of their ranges (each colour
    channel one term)."""
    errors = [
        ((params[p.name] - truth[p.name]).abs() / (p.high - p.low)).reshape(-1) for p in material.params if p.texture
    ]
    return float(torch.cat(errors).mean())


def measure(per_preset: int = 3, steps: int = 60, seed: int = 0, presets=PRESETS):
    rng = np.random.default_rng(seed)
    rows = []
    start = time.perf_counter()
    retrieve(np.full((64, 64, 3), 0.5, np.float32))  # the library's descriptors, once
    library_seconds = time.perf_counter() - start
    for preset in presets:
        for _ in range(per_preset):
            crop, truth, transform = synthetic_crop(preset, rng)
            t0 = time.perf_counter()
            best = retrieve(crop)[0]
            t1 = time.perf_counter()
            row = {
                "preset": preset.name,
                "material": preset.material,
                "found": best.preset.name,
                "type_ok": best.preset.material == preset.material,
                "retrieve_s": t1 - t0,
            }
            if row["type_ok"]:
                row["scale_octaves"] = abs(math.log2(best.transform.scale / transform.scale))
                symmetry = SYMMETRY[preset.material]
                if symmetry:
                    row["rotation_deg"] = rotation_error(best.transform.rotation_deg, transform.rotation_deg, symmetry)
                result = fit(best.preset.type, best.preset.params(), best.transform, crop, steps=steps)
                true_colour = mean_albedo(preset.type, truth)
                row["colour_init"] = float((mean_albedo(preset.type, best.preset.params()) - true_colour).abs().max())
                row["colour_fit"] = float((mean_albedo(preset.type, result.params) - true_colour).abs().max())
                row["param_init"] = parameter_error(preset.type, best.preset.params(), truth)
                row["param_fit"] = parameter_error(preset.type, result.params, truth)
                row["loss_init"], row["loss_fit"] = result.losses[0], result.losses[-1]
                row["fit_s"] = result.seconds
            rows.append(row)
    return rows, library_seconds


def summary(rows, library_seconds) -> str:
    ok = [r for r in rows if r["type_ok"]]
    col = lambda key: np.array([r[key] for r in ok if key in r])
    lines = [
        f"crops {len(rows)}; material top-1 {len(ok) / len(rows):.3f}; "
        f"preset top-1 {np.mean([r['found'] == r['preset'] for r in rows]):.3f}",
        f"scale error (octaves) median {np.median(col('scale_octaves')):.3f}, "
        f"within 0.25: {np.mean(col('scale_octaves') <= 0.25):.3f}, max {col('scale_octaves').max():.2f}",
        f"rotation error (deg, modulo symmetry) median {np.median(col('rotation_deg')):.1f}, "
        f"within 10: {np.mean(col('rotation_deg') <= 10):.3f}",
        f"mean albedo error (max channel) preset {np.median(col('colour_init')):.4f} median / "
        f"{col('colour_init').max():.4f} max -> fit {np.median(col('colour_fit')):.4f} median / "
        f"{col('colour_fit').max():.4f} max",
        f"texture parameter error (mean, fraction of range) preset {np.median(col('param_init')):.4f} median -> "
        f"fit {np.median(col('param_fit')):.4f} median",
        f"loss ratio fit/initial median {np.median(col('loss_fit') / col('loss_init')):.3f}",
        f"seconds: library descriptors {library_seconds:.1f}, "
        f"retrieval {np.median([r['retrieve_s'] for r in rows]):.2f} median per crop, "
        f"fit {np.median(col('fit_s')):.2f} median",
    ]
    misses = [f"{r['preset']}->{r['found']}" for r in rows if not r["type_ok"]]
    if misses:
        lines.append("misses: " + ", ".join(misses))
    return "\n".join(lines)


if __name__ == "__main__":
    torch.set_num_threads(1)
    args = [int(a) for a in sys.argv[1:]]
    rows, library_seconds = measure(*args)
    print(summary(rows, library_seconds))

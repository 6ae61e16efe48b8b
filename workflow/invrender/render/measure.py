"""How renders are measured, shared by the benchmarks (bench/) and the accuracy stage: a clock,
the agreement of two noisy images, the rows of a measurement as CSV."""

from __future__ import annotations

import csv
import json
import math
import time
import warnings
from pathlib import Path

import numpy as np


def quiet_pyopencl():
    # Renderer.render looks its kernel up per call; pyopencl warns each time (a cost we measure).
    warnings.filterwarnings("ignore", message=".*has been retrieved more than once.*")


def clock(fn, *args, **kwargs):
    """(result, wall seconds, CPU seconds of this process: all its threads)."""
    wall, cpu = time.perf_counter(), time.process_time()
    out = fn(*args, **kwargs)
    return out, time.perf_counter() - wall, time.process_time() - cpu


def agreement(
    a: np.ndarray, b: np.ndarray, var_a: float, var_b: float, mean_var_a: float = 0.0, mean_var_b: float = 0.0
) -> dict:
    """How two estimates of one image differ: relative difference of the image means with its
    1-sigma noise, per channel, and the per-pixel RMS difference beyond what the noise explains.

    var_* = mean per-pixel noise variance of each image; mean_var_* = variance of each image's
    overall mean estimated from independent repeats (catches the heavy tails and pixel
    correlations that the independent-pixel estimate var / n misses); sigma uses the larger.
    """
    mean_b = float(b.mean())
    n = a.size
    rel = float((a.mean() - mean_b) / mean_b)
    sigma = math.sqrt(max((var_a + var_b) / n, mean_var_a + mean_var_b)) / mean_b
    per_channel = ((a.mean((0, 1)) - b.mean((0, 1))) / b.mean((0, 1))).tolist()
    mse = float(np.mean((a - b) ** 2))
    return {
        "mean_rel_diff": rel,
        "mean_rel_sigma": sigma,
        "channel_rel_diff": per_channel,
        "pixel_mse_over_noise": mse / max(var_a + var_b, 1e-30),
        "pixel_excess_rmse": math.sqrt(max(0.0, mse - var_a - var_b)),
    }


def write_csv(path: Path, rows: list[dict]):
    keys = []
    for row in rows:
        keys += [k for k in row if k not in keys]
    with open(path, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=keys)
        writer.writeheader()
        for row in rows:
            writer.writerow({k: json.dumps(v) if isinstance(v, (list, dict)) else v for k, v in row.items()})

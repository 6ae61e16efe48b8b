"""`invrender bench render`: the forward renderer against Mitsuba 3, in the same run.

Four measurements on the synthetic room (``synthesize.room``, its view 2: glossy table, window
with sky and sun, floor, walls), each printed as a table and written under ``--out``
(``render.json`` with everything, one CSV per table, ``render_rmse_vs_time.png`` if matplotlib
is installed). docs/benchmarks.md ("Renderer") has the method, a full run and its reading.

1. **Time to equal RMSE** against Mitsuba's ``path`` integrator (``llvm_ad_rgb``; ``scalar_rgb``
   at a reduced size if LLVM is unusable, said in the output) for 3 and 10 bounces.
   Reference: the inverse-variance weighted mean of both renderers' converged images, each
   rendered as two independent halves. Why both: it costs each renderer the same, halves the
   reference noise against one renderer alone, and the bias check needs both converged images
   anyway; as long as the two agree (checked and printed: relative difference of the image
   means, and the per-pixel difference beyond noise) it favours neither. The reference's own
   noise (estimated from the half-image differences) is subtracted from every MSE.
   Each renderer then renders a ladder of spp, interleaved (A B, B A, ...) so both see the same
   machine load, `repeats` times each with new seeds, the (spp, repeat) jobs in shuffled order;
   time = median wall clock of one render call. The time at the target RMSE (the lower RMSE
   both ladders reach) is interpolated log-log between rungs; beside it, the same from a fit
   RMSE = k / sqrt(spp), t = a + b spp (c / sqrt(t) with a fixed per-call cost), and from
   process CPU time instead of wall clock (less sensitive to other processes on the machine).
   Excluded from the per-render times and reported separately as one-time costs: invrender's
   scene packing (BVH build, emitter BVH, sampling tables), buffer upload and kernel build, and
   its first launch; Mitsuba's scene conversion (our bridge), ``load_dict`` (its BVH build) and
   its first render (JIT compilation of the kernel, or drjit's kernel cache lookup).
2. **BVH build** of the room subdivided to ~200 k and ~1 M triangles, in a subprocess per size:
   build time, peak traced allocation (tracemalloc) and peak RSS growth during the build, bytes
   per triangle of the device buffers, and one-bounce render throughput of both renderers.
3. **Effects on demand** on three scenes (all-diffuse closed room, the diffuse room with its
   window, the glossy room): the analysed kernel against the all-features kernel and against
   each single switch (an effect compiled out turned on, one compiled in dropped, NEE against
   MILO's mixture, Russian roulette on and off): time and variance per sample, efficiency, and
   the image difference (the bias a switch introduces). Alone: ``python -m
   invrender.bench.render features-only [--quick] [--out DIR]``.
4. **Profile**: where invrender's time and variance go (sampling strategies compiled out,
   mixture weights, one-bounce ray throughput against Mitsuba).

What it shares with the other benchmarks (clocks, seeds, the Mitsuba variant, the time-to-equal-
error arithmetic, the report) is harness.py.
"""

from __future__ import annotations

import argparse
import logging
import math
import os
import sys
import time
import warnings
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np
from tqdm import tqdm

from ..render.features import COMPILED_IN_OFF
from ..render.measure import agreement
from .harness import (
    PeakRSS,
    clock,
    fit_model,
    median,
    model_time,
    next_seed_block,
    plot,
    print_probe,
    quiet_pyopencl,
    room_scene,
    run_probe,
    run_report,
    scene_buffer_bytes,
    start_run,
    time_at_rmse,
    verdict,
    write_report,
)

log = logging.getLogger("invrender.bench")

ROOM_VIEW = 2  # the room view that shows the glossy table, the window, floor and walls
LAUNCH_SAMPLES = 2_000_000  # path samples per launch / Mitsuba pass (as render/renderer.py)
PROBE_MARK = "BVHPROBE "
MIXTURE = "invrender mixture"  # the runner of Features(nee=False) in the equal-RMSE ladder
MITSUBA_SPLIT = "mitsuba, our light split"  # Mitsuba with the envmap's sampling_weight set to our split


@dataclass(frozen=True)
class Settings:
    mode: str
    width: int | None = None  # None: the room's default camera (96 x 72)
    height: int | None = None
    view: int = ROOM_VIEW
    bounces: tuple = (3, 10)
    ladder: tuple = (1, 2, 4, 8, 16, 32, 64, 128, 256)
    repeats: int = 5
    ref_spp_invrender: int = 8192  # per renderer, rendered as two halves
    ref_spp_mitsuba: int = 8192
    bvh_triangles: tuple = (200_000, 1_000_000)
    bvh_repeats: int = 3
    bvh_mitsuba: bool = True
    throughput_spp: int = 16
    throughput_repeats: int = 3
    feature_spp: int = 64
    feature_repeats: int = 5
    profile_spp: int = 64
    profile_repeats: int = 5


FULL = Settings("full", repeats=7, throughput_spp=64, feature_spp=128, feature_repeats=8)
QUICK = Settings(
    "quick",
    width=32,
    height=24,
    ladder=(1, 2, 4, 8),
    repeats=3,
    ref_spp_invrender=256,
    ref_spp_mitsuba=256,
    bvh_triangles=(20_000,),
    bvh_repeats=1,
    throughput_spp=2,
    throughput_repeats=2,
    feature_spp=8,
    feature_repeats=2,
    profile_spp=8,
    profile_repeats=2,
)


def scalar_settings(settings: Settings) -> Settings:
    """Mitsuba's scalar_rgb calls the Python BSDF plugin per sample (~70x slower than llvm):
    a smaller image, a shorter ladder and a smaller Mitsuba reference."""
    quick = settings.mode == "quick"
    return replace(
        settings,
        width=16 if quick else 32,
        height=12 if quick else 24,
        ladder=(1, 2, 4) if quick else (1, 2, 4, 8, 16, 32),
        ref_spp_mitsuba=32 if quick else 512,
        bvh_mitsuba=False,
    )


# ---------------------------------------------------------------------------------------------
# Small helpers
# ---------------------------------------------------------------------------------------------


def diffuse_variant(scene, window: bool = False):
    """The room with ks = 0, kw = 0 and kg = 0: Lambertian, no window, no sky (the window quad
    becomes a black patch of wall); with `window`, ks = 0 only (window and sky kept)."""
    from ..scene.types import Maps, Scene

    m = scene.maps
    kw, kg = (m.kw, m.kg) if window else (np.zeros_like(m.kw), np.zeros_like(m.kg))
    maps = Maps(kd=m.kd, ks=np.zeros_like(m.ks), ka=m.ka, ke=m.ke, kw=kw, kg=kg)
    return Scene(scene.mesh, maps, scene.cameras)


def subdivide_mesh(mesh, n: int):
    """Split every triangle into n^2 (each edge into n segments), UVs and instance ids carried.

    Watertight: a point on an edge is summed from the three corners in global vertex order with
    weights k / n, the third weight exactly 0, so the two faces sharing the edge compute the
    same float64 value, hence the same float32 vertex.
    """
    from ..scene.types import Mesh

    if n <= 1:
        return mesh
    faces = np.asarray(mesh.faces, np.int64)
    ii, jj = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = ii + jj <= n
    i, j = ii[keep], jj[keep]
    index = -np.ones((n + 1, n + 1), np.int64)
    index[i, j] = np.arange(len(i))
    weights = np.stack([n - i - j, i, j], -1) / n  # (P, 3) against corners in face order

    perm = np.argsort(faces, axis=1, kind="stable")  # corners in global vertex order
    w_sorted = np.take_along_axis(weights[None, :, :].repeat(len(faces), 0), perm[:, None, :].repeat(len(i), 1), 2)

    def interpolate(values):
        corners = np.asarray(values, np.float64)[np.take_along_axis(faces, perm, 1)]  # (F, 3, C)
        out = w_sorted[..., 0:1] * corners[:, None, 0]
        out = out + w_sorted[..., 1:2] * corners[:, None, 1]
        out = out + w_sorted[..., 2:3] * corners[:, None, 2]
        return out.reshape(-1, corners.shape[-1])

    positions = interpolate(mesh.positions).astype(np.float32)
    uvs = interpolate(mesh.uvs).astype(np.float32)
    local = []
    for a in range(n):
        for b in range(n - a):
            local.append((index[a, b], index[a + 1, b], index[a, b + 1]))
            if a + b < n - 1:
                local.append((index[a + 1, b], index[a + 1, b + 1], index[a, b + 1]))
    local = np.asarray(local, np.int64)  # (n^2, 3), same winding as the face
    new_faces = (np.arange(len(faces))[:, None, None] * len(i) + local[None]).reshape(-1, 3).astype(np.int32)
    instances = None if mesh.instance_ids is None else np.repeat(np.asarray(mesh.instance_ids, np.int32), n * n)
    return Mesh(positions=positions, faces=new_faces, uvs=uvs, instance_ids=instances)


def subdivisions_for(base_triangles: int, target: int) -> int:
    return max(1, int(round(math.sqrt(target / base_triangles))))


def _kernel_cached(features, device=None) -> str:
    """Whether the render kernel for these features is in the binary cache already ("hit",
    "miss"; "unknown" if render/program.py's private key function changed)."""
    try:
        from ..render.device import context_and_queue
        from ..render.program import _cache_key, assemble_source, cache_dir

        context, _ = context_and_queue(device)
        key = _cache_key(assemble_source("render.cl"), tuple(features.defines()), context.devices[0])
        return "hit" if (cache_dir() / f"{key}.bin").exists() else "miss"
    except Exception:  # noqa: BLE001 - informational only
        return "unknown"


# ---------------------------------------------------------------------------------------------
# The two renderers behind one interface: render(spp) -> (H, W, 3), fresh seeds on every call
# ---------------------------------------------------------------------------------------------


class InvrenderRunner:
    name = "invrender"

    def __init__(self, scene, camera, features, device=None, host=None, w_env=None, w_emit=None):
        from ..render.renderer import Renderer
        from ..render.scene_buffers import HostScene

        quiet_pyopencl()
        self.camera, self.features, self.one_time = camera, features, {}
        if host is None:
            host, self.one_time["pack_s"], _ = clock(HostScene.pack, scene.mesh, scene.maps)
        self.one_time["kernel_cache"] = _kernel_cached(features, device)
        self.renderer, self.one_time["init_s"], _ = clock(Renderer, scene, features, device, w_env, w_emit, host)
        self._seed = next_seed_block()

    def render_full(self, spp: int) -> dict:
        self._seed += 1
        return self.renderer.render(self.camera, int(spp), self._seed, aovs=False)

    def render(self, spp: int) -> np.ndarray:
        return self.render_full(spp)["radiance"]

    def warm_up(self):
        _, self.one_time["first_render_s"], _ = clock(self.render, 1)


class MitsubaRunner:
    name = "mitsuba"

    def __init__(self, scene, camera, bounces, variant, roulette_depth=0, sky_share=None):
        from .. import mitsuba as bridge  # noqa: I001 - first: it points drjit at a usable libLLVM
        import mitsuba as mi

        self.mi, self.camera, self.one_time = mi, camera, {}
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            scene_dict, self.one_time["convert_s"], _ = clock(
                bridge.scene_to_mitsuba,
                scene,
                camera,
                bounces,
                1,
                variant,
                roulette_depth=roulette_depth,
                sky_share=sky_share,
            )
        self.bridge_warnings = sorted({str(w.message) for w in caught})
        self.scene, self.one_time["load_s"], _ = clock(mi.load_dict, scene_dict, parallel=False)
        self.per_pass = max(1, LAUNCH_SAMPLES // (camera.width * camera.height))
        self._seed = next_seed_block()

    def render(self, spp: int) -> np.ndarray:
        """Passes of at most LAUNCH_SAMPLES path samples (as invrender's launches), averaged."""
        total, done = None, 0
        while done < spp:
            count = min(self.per_pass, spp - done)
            self._seed += 1
            image = np.array(self.mi.render(self.scene, spp=count, seed=self._seed % 2**32), dtype=np.float64)[..., :3]
            total = image * count if total is None else total + image * count
            done += count
        return (total / spp).astype(np.float32)

    def warm_up(self):
        _, self.one_time["first_render_s"], _ = clock(self.render, 1)


# ---------------------------------------------------------------------------------------------
# 1. Time to equal RMSE
# ---------------------------------------------------------------------------------------------


def reference(runners, spps, progress_desc):
    """Two independent halves per renderer -> inverse-variance weighted mean, its noise MSE,
    each renderer's converged mean and noise, and the render times."""
    converged = {}
    jobs = [(runner, spp // 2, half) for runner, spp in zip(runners, spps) for half in (0, 1)]
    halves = {}
    for runner, spp, half in tqdm(jobs, desc=progress_desc, unit="half", leave=False):
        image, wall, _ = clock(runner.render, max(1, spp))
        halves.setdefault(runner.name, []).append((image.astype(np.float64), wall, max(1, spp)))
    for name, ((a, wa, n), (b, wb, _)) in halves.items():
        noise = float(np.mean((a - b) ** 2) / 4.0)  # MSE of (a + b) / 2 from its own noise
        converged[name] = {
            "image": (a + b) / 2,
            "noise_mse": max(noise, 1e-30),
            "spp": 2 * n,
            "mean_var": float((a.mean() - b.mean()) ** 2 / 4.0),
            "seconds": wa + wb,
            "samples_per_s": 2 * n * a.shape[0] * a.shape[1] / (wa + wb),
        }
    weights = {name: 1.0 / c["noise_mse"] for name, c in converged.items()}
    total = sum(weights.values())
    ref = sum(weights[name] * c["image"] for name, c in converged.items()) / total
    return ref, 1.0 / total, converged


def equal_rmse(scene, camera, bounces: int, settings: Settings, variant: str, device=None):
    from ..render.analysis import analyse

    features = analyse(scene, device=device).with_bounces(bounces)
    inv = InvrenderRunner(scene, camera, features, device)
    inv.warm_up()
    mit = MitsubaRunner(scene, camera, bounces, variant, features.roulette_depth)
    mit.warm_up()
    runners = (inv, mit)
    # MILO's one-sample mixture, with its own pilot-chosen weights, in the same ladder (not in
    # the reference): which estimator wins decides Features.nee's default.
    mixture_features = analyse(scene, overrides={"nee": False}, device=device).with_bounces(bounces)
    mix = InvrenderRunner(scene, camera, mixture_features, device)
    mix.name = MIXTURE
    mix.warm_up()
    # Mitsuba told our light split (the envmap's sampling_weight): what the ratio owes to the split.
    share = features.w_env / max(features.w_env + features.w_emit, 1e-30)
    mit_split = MitsubaRunner(scene, camera, bounces, variant, features.roulette_depth, sky_share=share)
    mit_split.name = MITSUBA_SPLIT
    mit_split.warm_up()

    ref, ref_noise, converged = reference(
        runners, (settings.ref_spp_invrender, settings.ref_spp_mitsuba), f"reference B={bounces}"
    )
    check = agreement(
        converged["invrender"]["image"],
        converged["mitsuba"]["image"],
        converged["invrender"]["noise_mse"],
        converged["mitsuba"]["noise_mse"],
        converged["invrender"]["mean_var"],
        converged["mitsuba"]["mean_var"],
    )

    # Steady-state 1-spp time, to tell the first render's one-time part from its work.
    records = []
    jobs = [(spp, rep) for spp in settings.ladder for rep in range(settings.repeats)]
    # Shuffled: a burst of load from other processes hits a few renders of many rungs, not all
    # repeats of one rung (the medians absorb the former).
    jobs = [jobs[i] for i in np.random.default_rng(0).permutation(len(jobs))]
    ladder = (inv, mix, mit, mit_split)
    for spp, rep in tqdm(jobs, desc=f"ladder B={bounces}", unit="render", leave=False):
        for runner in ladder if rep % 2 == 0 else ladder[::-1]:
            image, wall, cpu = clock(runner.render, spp)
            mse = float(np.mean((image.astype(np.float64) - ref) ** 2))
            records.append({"renderer": runner.name, "spp": spp, "wall": wall, "cpu": cpu, "mse": mse})

    pixels = camera.width * camera.height
    curves, summary = [], {}
    for runner in ladder:
        rows = []
        for spp in settings.ladder:
            mine = [r for r in records if r["renderer"] == runner.name and r["spp"] == spp]
            walls = [r["wall"] for r in mine]
            mse_raw = float(np.mean([r["mse"] for r in mine]))
            mse = max(mse_raw - ref_noise, 1e-3 * mse_raw)  # the reference's own noise removed
            rows.append(
                {
                    "section": "curves",
                    "bounces": bounces,
                    "renderer": runner.name,
                    "spp": spp,
                    "wall_s": median(walls),
                    "wall_min_s": min(walls),
                    "wall_max_s": max(walls),
                    "cpu_s": median([r["cpu"] for r in mine]),
                    "rmse": math.sqrt(mse),
                    "rmse_raw": math.sqrt(mse_raw),
                    "repeats": len(mine),
                }
            )
        curves += rows
        top = rows[-1]
        summary[runner.name] = {
            "times": [r["wall_s"] for r in rows],
            "rmses": [r["rmse"] for r in rows],
            "cpu_times": [r["cpu_s"] for r in rows],
            "samples_per_s": pixels * top["spp"] / top["wall_s"],
            "cpu_per_wall": top["cpu_s"] / top["wall_s"],
            "var_per_sample": top["rmse"] ** 2 * top["spp"],
        }
    target = max(summary[name]["rmses"][-1] for name in summary)
    t_inv, extra_inv = time_at_rmse(summary["invrender"]["times"], summary["invrender"]["rmses"], target)
    t_mit, extra_mit = time_at_rmse(summary["mitsuba"]["times"], summary["mitsuba"]["rmses"], target)
    cpu_inv, _ = time_at_rmse(summary["invrender"]["cpu_times"], summary["invrender"]["rmses"], target)
    cpu_mit, _ = time_at_rmse(summary["mitsuba"]["cpu_times"], summary["mitsuba"]["rmses"], target)
    model = {name: fit_model(settings.ladder, summary[name]["times"], summary[name]["rmses"]) for name in summary}
    t_fit = {name: model_time(m, target) for name, m in model.items()}
    t_mix, extra_mix = time_at_rmse(summary[MIXTURE]["times"], summary[MIXTURE]["rmses"], target)
    t_split, extra_split = time_at_rmse(summary[MITSUBA_SPLIT]["times"], summary[MITSUBA_SPLIT]["rmses"], target)
    s_inv, s_mit, s_mix = summary["invrender"], summary["mitsuba"], summary[MIXTURE]
    row = {
        "section": "equal_rmse",
        "bounces": bounces,
        "mitsuba_variant": variant,
        "width": camera.width,
        "height": camera.height,
        "target_rmse": target,
        "t_invrender_s": t_inv,
        "t_mitsuba_s": t_mit,
        "ratio": t_mit / t_inv,
        "ratio_fit": t_fit["mitsuba"] / t_fit["invrender"],
        "fit_invrender": model["invrender"],
        "fit_mitsuba": model["mitsuba"],
        "ratio_cpu": cpu_mit / cpu_inv,
        "extrapolated": bool(extra_inv or extra_mit or extra_mix or extra_split),
        "t_mitsuba_split_s": t_split,
        "ratio_mitsuba_split": t_split / t_inv,
        "ratio_mitsuba_split_fit": t_fit[MITSUBA_SPLIT] / t_fit["invrender"],
        "var_per_sample_mitsuba_split": summary[MITSUBA_SPLIT]["var_per_sample"],
        "t_mixture_s": t_mix,
        "ratio_mixture": t_mit / t_mix,
        "ratio_mixture_fit": t_fit["mitsuba"] / t_fit[MIXTURE],
        "var_per_sample_mixture": s_mix["var_per_sample"],
        "samples_per_s_mixture": s_mix["samples_per_s"],
        "weights": f"{features.w_env:g}/{features.w_emit:g}",
        "weights_mixture": f"{mixture_features.w_env:g}/{mixture_features.w_emit:g}",
        "samples_per_s_invrender": s_inv["samples_per_s"],
        "samples_per_s_mitsuba": s_mit["samples_per_s"],
        "speed_ratio": s_inv["samples_per_s"] / s_mit["samples_per_s"],
        "var_per_sample_invrender": s_inv["var_per_sample"],
        "var_per_sample_mitsuba": s_mit["var_per_sample"],
        "variance_ratio": s_mit["var_per_sample"] / s_inv["var_per_sample"],
        "cpu_per_wall_invrender": s_inv["cpu_per_wall"],
        "cpu_per_wall_mitsuba": s_mit["cpu_per_wall"],
        "ref_noise_rmse": math.sqrt(ref_noise),
        "ref_spp_invrender": converged["invrender"]["spp"],
        "ref_spp_mitsuba": converged["mitsuba"]["spp"],
        "mean_rel_diff": check["mean_rel_diff"],
        "mean_rel_sigma": check["mean_rel_sigma"],
        "channel_rel_diff": check["channel_rel_diff"],
        "pixel_excess_rmse": check["pixel_excess_rmse"],
        "pixel_mse_over_noise": check["pixel_mse_over_noise"],
        "agreement": verdict(check, min(c["spp"] for c in converged.values())),
        "features": asdict(features),
        "bridge_warnings": mit.bridge_warnings,
    }
    one_steady = {
        name: median([r["wall"] for r in records if r["renderer"] == name and r["spp"] == settings.ladder[0]])
        for name in ("invrender", "mitsuba")
    }
    one_time = [
        {
            "section": "one_time",
            "bounces": bounces,
            "renderer": "invrender",
            "scene_s": inv.one_time["pack_s"],
            "scene_what": "HostScene.pack (BVH, emitter BVH, tables)",
            "setup_s": inv.one_time["init_s"],
            "setup_what": f"upload + kernel build (binary cache {inv.one_time['kernel_cache']})",
            "first_render_s": inv.one_time["first_render_s"],
            "steady_render_s": one_steady["invrender"],
            "reference_samples_per_s": converged["invrender"]["samples_per_s"],
        },
        {
            "section": "one_time",
            "bounces": bounces,
            "renderer": f"mitsuba {variant}",
            "scene_s": mit.one_time["convert_s"],
            "scene_what": "scene_to_mitsuba (our bridge)",
            "setup_s": mit.one_time["load_s"],
            "setup_what": "mi.load_dict (plugins, BVH)",
            "first_render_s": mit.one_time["first_render_s"],
            "steady_render_s": one_steady["mitsuba"],
            "reference_samples_per_s": converged["mitsuba"]["samples_per_s"],
        },
    ]
    if row["agreement"] == "DIFFER":
        log.error(
            "B=%d: the converged images differ by %.2f %% in their mean (> 1 %%): a bug in one renderer "
            "or the bridge, not noise (sigma %.3f %%)",
            bounces,
            100 * check["mean_rel_diff"],
            100 * check["mean_rel_sigma"],
        )
    return row, curves, one_time


# ---------------------------------------------------------------------------------------------
# 2. BVH build and throughput at scale (one subprocess per size)
# ---------------------------------------------------------------------------------------------


def bvh_probe(triangles: int, settings: Settings, device=None, variant: str | None = None) -> dict:
    """Runs in its own process (`python -m invrender.bench.render bvh-probe`), so that peak
    memory is the build's and nothing else's."""
    import tracemalloc

    from ..render.bvh import build_bvh, triangle_vertices
    from ..render.features import Features
    from ..render.scene_buffers import HostScene
    from ..scene.types import Scene

    base, _ = room_scene(settings.width, settings.height)
    n = subdivisions_for(len(base.mesh.faces), triangles)
    mesh = subdivide_mesh(base.mesh, n)
    scene = Scene(mesh, base.maps, base.cameras)
    camera = scene.cameras[settings.view]
    v = triangle_vertices(mesh.positions, mesh.faces)

    with PeakRSS() as rss:
        bvh, wall, _ = clock(build_bvh, *v)
    walls = [wall] + [clock(build_bvh, *v)[1] for _ in range(settings.bvh_repeats - 1)]
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    build_bvh(*v)
    traced_peak = tracemalloc.get_traced_memory()[1] - before
    tracemalloc.stop()

    host, pack_wall, _ = clock(HostScene.pack, mesh, scene.maps, bvh)
    total_bytes, geometry_bytes = scene_buffer_bytes(host)
    result = {
        "section": "bvh",
        "triangles": int(len(mesh.faces)),
        "subdivision": n,
        "build_s": median(walls),
        "build_runs": len(walls),
        "nodes": bvh.n_nodes,
        "sah_cost": bvh.sah_cost(),
        "traced_peak_mb": traced_peak / 2**20,
        "rss_growth_mb": rss.growth / 2**20,
        "pack_rest_s": pack_wall,
        "emitters": int(host.num_emitters),
        "device_mb": total_bytes / 2**20,
        "geometry_bytes_per_tri": geometry_bytes / len(mesh.faces),
        "device_bytes_per_tri": total_bytes / len(mesh.faces),
    }

    # One bounce: camera ray + one scattered ray per sample (2 closest-hit traversals).
    pixels = camera.width * camera.height
    bare = Features.only(max_bounces=1, emission=True, environment=True, window=True)
    for key, features in (("bare", bare), ("all", Features.everything(max_bounces=1))):
        runner = InvrenderRunner(scene, camera, features, device, host=host)
        runner.warm_up()
        times = [clock(runner.render, settings.throughput_spp)[1] for _ in range(settings.throughput_repeats)]
        rate = pixels * settings.throughput_spp / median(times)
        result[f"invrender_{key}_samples_per_s"] = rate
        result[f"invrender_{key}_rays_per_s"] = 2 * rate
    if variant and settings.bvh_mitsuba:
        runner = MitsubaRunner(scene, camera, 1, variant)
        runner.warm_up()
        times = [clock(runner.render, settings.throughput_spp)[1] for _ in range(settings.throughput_repeats)]
        rate = pixels * settings.throughput_spp / median(times)
        result["mitsuba_load_s"] = runner.one_time["load_s"]
        result["mitsuba_samples_per_s"] = rate
        result["mitsuba_rays_per_s"] = 3 * rate  # camera ray, the emitter sample's shadow ray, the BSDF ray
    return result


def bvh_section(settings: Settings, variant: str, device=None) -> list[dict]:
    rows = []
    for triangles in tqdm(settings.bvh_triangles, desc="bvh sizes", unit="size", leave=False):
        args = ["bvh-probe", "--triangles", triangles, "--mode", settings.mode, "--variant", variant]
        if settings.width:
            args += ["--width", settings.width, "--height", settings.height]
        if not settings.bvh_mitsuba:
            args += ["--no-mitsuba"]
        if device:
            args += ["--device", device]
        rows.append(run_probe("invrender.bench.render", args, PROBE_MARK, f"bvh probe ({triangles} triangles)"))
    return rows


# ---------------------------------------------------------------------------------------------
# 3. Effects on demand: the specialised kernel against everything, and each switch on its own
# ---------------------------------------------------------------------------------------------


def _interleaved(runners, spp, repeats, desc):
    """Render with each runner `repeats` times, alternating the order; per runner: median wall
    time, the mean image and the mean per-pixel noise variance of that mean."""
    out = {id(r): {"walls": [], "images": [], "variances": []} for r in runners}
    for rep in tqdm(range(repeats), desc=desc, unit="round", leave=False):
        for runner in runners if rep % 2 == 0 else runners[::-1]:
            result, wall, _ = clock(runner.render_full, spp)
            out[id(runner)]["walls"].append(wall)
            out[id(runner)]["images"].append(result["radiance"].astype(np.float64))
            out[id(runner)]["variances"].append(result["variance"].astype(np.float64))
    stats = []
    for runner in runners:
        o = out[id(runner)]
        means = [image.mean() for image in o["images"]]
        stats.append(
            {
                "wall": median(o["walls"]),
                "walls": o["walls"],  # per round, in round order: paired ratios between runners
                "image": np.mean(o["images"], 0),
                "mean_var": float(np.var(means, ddof=1) / len(means)) if len(means) > 1 else 0.0,
                "var_mean": float(np.mean(o["variances"]) / len(o["images"])),
                "var_per_sample": float(np.mean(o["variances"]) * spp),
            }
        )
    return stats


# The three scenes of the effects table: (name, the room -> that scene).
EFFECT_SCENES = (
    ("all-diffuse closed room", diffuse_variant),
    ("diffuse room with window", lambda room: diffuse_variant(room, window=True)),
    ("glossy room", lambda room: room),
)
# Effects the analysis compiled out, turned back on: name -> the flags that switch it on (an
# effect with the effect it needs: window and env sampling need the environment).
UNNEEDED_ON = (
    ("specular", {"specular": True}),
    ("emission", {"emission": True}),
    ("emitter_sampling", {"emitter_sampling": True}),
    ("environment", {"environment": True}),
    ("window", {"environment": True, "window": True}),
    ("env_sampling", {"environment": True, "env_sampling": True}),
    ("one_sided", {"one_sided": True}),
)
ROULETTE_BOUNCES, ROULETTE_DEPTH = 10, 3


def effect_switches(scene, analysed, device=None) -> list[tuple[str, str, object]]:
    """(switch, kind, Features) for one scene, the analysed kernel first. Every variant keeps
    the analysed weights and roulette but for what it changes, so its row measures one switch."""
    from ..render.features import Features
    from ..render.tuning import choose_strategy_weights

    same = {"w_env": analysed.w_env, "w_emit": analysed.w_emit, "roulette_depth": analysed.roulette_depth}
    off = ", ".join(k for k, v in asdict(analysed).items() if v is False) or "none"
    switches = [
        (f"analysed (compiled out: {off}; rr {analysed.roulette_depth})", "analysed", analysed),
        ("everything (Features.everything)", "control", replace(Features.everything(analysed.max_bounces), **same)),
    ]
    for effect, flags in UNNEEDED_ON:
        if not getattr(analysed, effect):
            switches.append((f"{effect} on", "unneeded", replace(analysed, **flags)))
    for name, kind, flags, applies in COMPILED_IN_OFF:
        if applies(analysed):
            switches.append((name, kind, replace(analysed, **flags)))
    # The estimator: MILO's one-sample mixture with the weights its own pilot picks.
    mixture, _ = choose_strategy_weights(scene, replace(analysed, nee=not analysed.nee), device)
    switches.append(("nee " + ("off (MILO mixture)" if analysed.nee else "on"), "estimator", mixture))
    # Russian roulette at B = 10: the analysed kernel if that is what it is, else both settings.
    rr_on = replace(analysed, max_bounces=ROULETTE_BOUNCES, roulette_depth=ROULETTE_DEPTH)
    if rr_on != analysed:
        switches.append((f"roulette {ROULETTE_DEPTH}, B = {ROULETTE_BOUNCES}", "roulette", rr_on))
    switches.append((f"roulette off, B = {ROULETTE_BOUNCES}", "roulette", replace(rr_on, roulette_depth=0)))
    return switches


def _switch_verdict(kind: str, check: dict, spp: int) -> str:
    """verdict(); for a switch that drops a term a difference is what is measured ("biased")."""
    judged = verdict(check, spp)
    return "biased" if kind == "bias" and judged == "DIFFER" else judged


def features_section(scene, camera, settings: Settings, device=None) -> list[dict]:
    """Per scene (EFFECT_SCENES): the analysed kernel, the all-features kernel and every single
    switch (effect_switches), rendered interleaved; time and variance per sample, efficiency
    1 / (variance x time) and the image difference, all against the analysed kernel."""
    from ..render.analysis import analyse_scene
    from ..render.scene_buffers import HostScene

    rows = []
    samples = camera.width * camera.height * settings.feature_spp
    judged_spp = settings.feature_spp * settings.feature_repeats
    for name, make in EFFECT_SCENES:
        variant_scene = make(scene)
        analysed, _ = analyse_scene(variant_scene, device=device)
        switches = effect_switches(variant_scene, analysed, device)
        host = HostScene.pack(variant_scene.mesh, variant_scene.maps)
        runners = [InvrenderRunner(variant_scene, camera, f, device, host=host) for _, _, f in switches]
        for runner in runners:
            runner.warm_up()
        stats = _interleaved(runners, settings.feature_spp, settings.feature_repeats, f"effects: {name}")
        base = stats[0]
        for (switch, kind, features), s in zip(switches, stats):
            check = agreement(
                s["image"], base["image"], s["var_mean"], base["var_mean"], s["mean_var"], base["mean_var"]
            )
            efficiency = (base["var_per_sample"] * base["wall"]) / (s["var_per_sample"] * s["wall"])
            # The speed-up's noise: the spread of the ratio within each round (renders minutes
            # apart on a shared machine see different loads; those of one round, less so).
            log_ratio = np.log(np.asarray(s["walls"]) / np.asarray(base["walls"]))
            spread = float(np.std(log_ratio, ddof=1) / math.sqrt(len(log_ratio))) if len(log_ratio) > 1 else None
            rows.append(
                {
                    "section": "features",
                    "scene": name,
                    "switch": switch,
                    "kind": kind,
                    "bounces": features.max_bounces,
                    "roulette_depth": features.roulette_depth,
                    "weights": f"{features.w_env:g}/{features.w_emit:g}",
                    "features": asdict(features),
                    "spp": settings.feature_spp,
                    "repeats": settings.feature_repeats,
                    "t_per_sample_us": 1e6 * s["wall"] / samples,
                    "speedup": s["wall"] / base["wall"],
                    "speedup_sigma": None
                    if kind == "analysed" or spread is None
                    else spread * s["wall"] / base["wall"],
                    "var_per_sample": s["var_per_sample"],
                    # at another image (a dropped term) variance x time compares nothing
                    "efficiency": None if kind == "bias" else efficiency,
                    "mean_rel_diff": None if kind == "analysed" else check["mean_rel_diff"],
                    "mean_rel_sigma": None if kind == "analysed" else check["mean_rel_sigma"],
                    "pixel_mse_over_noise": None if kind == "analysed" else check["pixel_mse_over_noise"],
                    "agreement": "-" if kind == "analysed" else _switch_verdict(kind, check, judged_spp),
                }
            )
            if rows[-1]["agreement"] == "DIFFER":
                log.error(
                    "effects, %s, %s: the image differs from the analysed kernel's by %.2f %% (> 1 %%, "
                    "sigma %.3f %%) where only the noise may change",
                    name,
                    switch,
                    100 * check["mean_rel_diff"],
                    100 * check["mean_rel_sigma"],
                )
    return rows


def effect_notes(rows) -> list[str]:
    """A note for each switch that should leave the image as it is and did not, or could not be
    told to within this run's noise."""
    return [
        f"effects, {row['scene']}, {row['switch']}: the image differs from the analysed kernel's by "
        f"{100 * row['mean_rel_diff']:+.2f} % (1 sigma {100 * row['mean_rel_sigma']:.2f} %): "
        + ("a bug, not noise" if row["agreement"] == "DIFFER" else "within the noise of this run")
        for row in rows
        if row["kind"] not in ("analysed", "bias") and row["agreement"] not in ("agree", "not checked")
    ]


def run_effects(quick: bool = False, out="docs/benchmarks", device: str | None = None, width=None, height=None):
    """Only the effects table (`python -m invrender.bench.render features-only`): no Mitsuba, so
    minutes instead of the whole benchmark's hour. Writes render_features.json, .csv, _table.md."""
    settings = QUICK if quick else FULL
    settings = replace(settings, width=width or settings.width, height=height or settings.height)
    quiet_pyopencl()
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    started, load_start = time.time(), os.getloadavg()
    scene, _ = room_scene(settings.width, settings.height)
    camera = scene.cameras[settings.view]
    rows = features_section(scene, camera, settings, device)
    report = run_report(
        "render_features", settings, "none", effect_notes(rows), started, load_start, device, {"features": rows}
    )
    title = (
        f"# invrender bench render, effects only ({settings.mode}; {camera.width}x{camera.height}, room view "
        f"{settings.view}; {settings.feature_spp} spp x {settings.feature_repeats} rounds; {report['seconds']:.0f} s)"
    )
    write_report(out, "render_features", title, report, TABLES, ("features",))
    return report


# ---------------------------------------------------------------------------------------------
# 4. Profile: where invrender's time and variance go
# ---------------------------------------------------------------------------------------------


def profile_section(scene, camera, settings: Settings, variant: str, device=None) -> list[dict]:
    from ..render.analysis import analyse
    from ..render.features import Features

    analysed = analyse(scene, device=device)
    bounces = analysed.max_bounces
    cases = [
        ("all features (analysed)", analysed, 0.25, 0.25, True),
        ("emitter sampling off", replace(analysed, emitter_sampling=False), 0.25, 0.0, True),
        ("env sampling off", replace(analysed, env_sampling=False), 0.0, 0.25, True),
        ("emitter + env sampling off", replace(analysed, emitter_sampling=False, env_sampling=False), 0.0, 0.0, True),
        # Compiled in but almost never drawn: the paths are those of "... sampling off", so the
        # time difference is the cost of evaluating the strategy's density at every vertex
        # (for the emitters, the all-hits traversal of their BVH).
        ("emitter density only (w_emit 0.001)", analysed, 0.25, 0.001, True),
        ("env density only (w_env 0.001)", analysed, 0.001, 0.25, True),
        ("weights env 0.1, emit 0.1", analysed, 0.1, 0.1, True),
        ("weights env 0.1, emit 0.4", analysed, 0.1, 0.4, True),
        ("weights env 0.4, emit 0.1", analysed, 0.4, 0.1, True),
        (
            "Lambertian, no sampling strategies",
            replace(analysed, specular=False, emitter_sampling=False, env_sampling=False),
            0.0,
            0.0,
            False,
        ),
    ]
    pixels = camera.width * camera.height
    host = None
    runners = []
    for name, features, w_env, w_emit, same_image in cases:
        runner = InvrenderRunner(scene, camera, features, device, host=host, w_env=w_env, w_emit=w_emit)
        host = runner.renderer.host
        runner.warm_up()
        runners.append(runner)
    stats = _interleaved(runners, settings.profile_spp, settings.profile_repeats, f"profile B={bounces}")
    base = stats[0]
    rows = []
    for (name, features, w_env, w_emit, same_image), s in zip(cases, stats):
        t = s["wall"] / (pixels * settings.profile_spp)
        rows.append(
            {
                "section": "profile",
                "case": name,
                "renderer": "invrender",
                "bounces": bounces,
                "t_per_sample_us": 1e6 * t,
                "var_per_sample": s["var_per_sample"],
                "efficiency_vs_all": (base["var_per_sample"] * base["wall"]) / (s["var_per_sample"] * s["wall"]),
                "time_vs_all": s["wall"] / base["wall"],
                "mean_rel_diff_vs_all": agreement(s["image"], base["image"], s["var_mean"], base["var_mean"])[
                    "mean_rel_diff"
                ]
                if same_image
                else None,
            }
        )

    # Mitsuba at the same depth: time and variance per sample from pairs of independent renders.
    mit = MitsubaRunner(scene, camera, bounces, variant, analysed.roulette_depth)
    mit.warm_up()
    walls, images = [], []
    for _ in tqdm(range(max(2, settings.profile_repeats)), desc="profile mitsuba", leave=False):
        image, wall, _ = clock(mit.render, settings.profile_spp)
        walls.append(wall)
        images.append(image.astype(np.float64))
    pair_var = np.mean([np.mean((images[k] - images[k + 1]) ** 2) / 2 for k in range(len(images) - 1)])
    t = median(walls) / (pixels * settings.profile_spp)
    var = float(pair_var * settings.profile_spp)
    rows.append(
        {
            "section": "profile",
            "case": f"mitsuba {variant} path",
            "renderer": "mitsuba",
            "bounces": bounces,
            "t_per_sample_us": 1e6 * t,
            "var_per_sample": var,
            "efficiency_vs_all": (base["var_per_sample"] * base["wall"] / (pixels * settings.profile_spp)) / (var * t),
            "time_vs_all": t / (base["wall"] / (pixels * settings.profile_spp)),
            "mean_rel_diff_vs_all": None,
        }
    )

    # One bounce (B = 1) ray throughput on the room as it is.
    bare = Features.only(max_bounces=1, emission=True, environment=True, window=True)
    one = [InvrenderRunner(scene, camera, f, device, host=host) for f in (bare, replace(analysed, max_bounces=1))]
    for r in one:
        r.warm_up()
    mit1 = MitsubaRunner(scene, camera, 1, variant)
    mit1.warm_up()
    spp = settings.profile_spp
    walls = {id(r): [] for r in (*one, mit1)}
    for rep in tqdm(range(settings.profile_repeats), desc="one-bounce throughput", leave=False):
        for r in (*one, mit1) if rep % 2 == 0 else (mit1, *one[::-1]):
            walls[id(r)].append(clock(r.render, spp)[1])
    for name, r, rays in (
        ("one bounce, Lambertian closest-hit only", one[0], 2),
        ("one bounce, all features", one[1], 2),
        (f"one bounce, mitsuba {variant} (max_depth 2)", mit1, 3),
    ):
        rate = pixels * spp / median(walls[id(r)])
        rows.append(
            {
                "section": "profile",
                "case": name,
                "renderer": r.name,
                "bounces": 1,
                "t_per_sample_us": 1e6 / rate,
                "rays_per_s": rays * rate,
                "samples_per_s": rate,
            }
        )
    return rows


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------

TABLES = {
    "equal_rmse": (
        "Time to equal RMSE (wall clock, median of repeats; ratio = t_mitsuba / t_invrender, > 1: invrender "
        "faster; invrender = next-event estimation, mixture = MILO's one-sample mixture)",
        [
            ("bounces", "B", "d"),
            ("width", "W", "d"),
            ("height", "H", "d"),
            ("target_rmse", "target RMSE", ".4g"),
            ("t_invrender_s", "t inv [s]", ".3g"),
            ("t_mitsuba_s", "t mi [s]", ".3g"),
            ("ratio", "ratio", ".3f"),
            ("ratio_fit", "ratio (fit)", ".3f"),
            ("ratio_cpu", "ratio (CPU time)", ".3f"),
            ("speed_ratio", "samples/s inv/mi", ".3f"),
            ("variance_ratio", "var/sample mi/inv", ".3f"),
            ("weights", "w_env/w_emit", "s"),
            ("t_mixture_s", "t mixture [s]", ".3g"),
            ("ratio_mixture", "ratio mixture", ".3f"),
            ("ratio_mixture_fit", "(fit)", ".3f"),
            ("weights_mixture", "mixture w_env/w_emit", "s"),
            ("ratio_mitsuba_split", "ratio vs mi with our split", ".3f"),
            ("ratio_mitsuba_split_fit", "(fit)", ".3f"),
            ("ref_noise_rmse", "ref noise RMSE", ".2g"),
            ("mean_rel_diff", "mean rel diff", "+.3%"),
            ("mean_rel_sigma", "(1 sigma)", ".3%"),
            ("agreement", "images", "s"),
            ("pixel_excess_rmse", "pixel bias RMSE", ".2g"),
        ],
    ),
    "one_time": (
        "One-time costs, excluded from the times above [s]",
        [
            ("bounces", "B", "d"),
            ("renderer", "renderer", "s"),
            ("scene_s", "scene", ".3f"),
            ("scene_what", "= what", "s"),
            ("setup_s", "setup", ".3f"),
            ("setup_what", "= what", "s"),
            ("first_render_s", "first render (1 spp)", ".3f"),
            ("steady_render_s", "later 1-spp render", ".4f"),
            ("reference_samples_per_s", "samples/s (reference)", ".3g"),
        ],
    ),
    "curves": (
        "RMSE against time (the ladders; RMSE with the reference's noise removed)",
        [
            ("bounces", "B", "d"),
            ("renderer", "renderer", "s"),
            ("spp", "spp", "d"),
            ("wall_s", "wall [s]", ".4f"),
            ("wall_min_s", "min", ".4f"),
            ("wall_max_s", "max", ".4f"),
            ("cpu_s", "cpu [s]", ".4f"),
            ("rmse", "RMSE", ".4g"),
            ("rmse_raw", "RMSE raw", ".4g"),
        ],
    ),
    "bvh": (
        "BVH build and one-bounce throughput at scale (room subdivided)",
        [
            ("triangles", "triangles", "d"),
            ("build_s", "build [s]", ".2f"),
            ("traced_peak_mb", "peak alloc [MB]", ".0f"),
            ("rss_growth_mb", "peak RSS growth [MB]", ".0f"),
            ("pack_rest_s", "rest of pack [s]", ".2f"),
            ("geometry_bytes_per_tri", "geometry B/tri", ".1f"),
            ("device_bytes_per_tri", "device B/tri", ".1f"),
            ("invrender_bare_rays_per_s", "inv rays/s bare", ".3g"),
            ("invrender_all_rays_per_s", "inv rays/s all", ".3g"),
            ("mitsuba_rays_per_s", "mi rays/s", ".3g"),
            ("mitsuba_load_s", "mi load [s]", ".2f"),
        ],
    ),
    "features": (
        "Effects on demand: each switch against the analysed (specialised) kernel, rendered interleaved "
        "(speed-up = t / t analysed, > 1: the switch costs time, +- 1 sigma from the per-round ratios; "
        "efficiency = 1 / (variance x time) relative to the analysed kernel; kind: control = "
        "Features.everything, unneeded = an effect the analysis compiled out turned on, bias = an effect "
        "compiled in dropped, variance = a sampling strategy dropped)",
        [
            ("scene", "scene", "s"),
            ("switch", "switch", "s"),
            ("kind", "kind", "s"),
            ("bounces", "B", "d"),
            ("weights", "w_env/w_emit", "s"),
            ("t_per_sample_us", "t/sample [us]", ".3f"),
            ("speedup", "speed-up", ".3f"),
            ("speedup_sigma", "(+-)", ".3f"),
            ("var_per_sample", "var/sample", ".4g"),
            ("efficiency", "efficiency", ".3f"),
            ("mean_rel_diff", "mean rel diff", "+.2%"),
            ("mean_rel_sigma", "(1 sigma)", ".2%"),
            ("pixel_mse_over_noise", "pixel MSE / noise", ".2f"),
            ("agreement", "verdict", "s"),
        ],
    ),
    "profile": (
        "Profile of invrender (default room): time, variance and efficiency = 1 / (variance x time) per sample",
        [
            ("case", "case", "s"),
            ("bounces", "B", "d"),
            ("t_per_sample_us", "t/sample [us]", ".3f"),
            ("var_per_sample", "var/sample", ".4g"),
            ("time_vs_all", "time vs all", ".3f"),
            ("efficiency_vs_all", "efficiency vs all", ".3f"),
            ("mean_rel_diff_vs_all", "mean rel diff", "+.2%"),
            ("rays_per_s", "rays/s", ".3g"),
        ],
    ),
}


# ---------------------------------------------------------------------------------------------
# The benchmark
# ---------------------------------------------------------------------------------------------


SECTIONS = ("equal_rmse", "bvh", "features", "profile")


def chosen_sections(sections: str | None) -> tuple[str, ...]:
    from ..scene.types import SceneError

    chosen = tuple(s.strip() for s in sections.split(",")) if sections else SECTIONS
    unknown = sorted(set(chosen) - set(SECTIONS))
    if unknown:
        raise SceneError("bench render --sections", ",".join(unknown), f"names among {', '.join(SECTIONS)}")
    return chosen


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None, sections: str | None = None) -> dict:
    chosen = chosen_sections(sections)
    settings, out, variant, notes, started, load_start = start_run(
        "render", QUICK if quick else FULL, out, scalar_settings
    )

    scene, _ = room_scene(settings.width, settings.height)
    camera = scene.cameras[settings.view]
    results = {"equal_rmse": [], "curves": [], "one_time": [], "bvh": [], "features": [], "profile": []}
    for bounces in tqdm(settings.bounces if "equal_rmse" in chosen else (), desc="equal RMSE", unit="B"):
        row, curves, one_time = equal_rmse(scene, camera, bounces, settings, variant, device)
        results["equal_rmse"].append(row)
        results["curves"] += curves
        results["one_time"] += one_time
        if row["agreement"] not in ("agree", "not checked"):
            notes.append(
                f"B={bounces}: converged invrender and Mitsuba images differ by "
                f"{100 * row['mean_rel_diff']:+.2f} % in their mean (1 sigma "
                f"{100 * row['mean_rel_sigma']:.2f} %): "
                + (
                    "a bug, not noise"
                    if row["agreement"] == "DIFFER"
                    else "within the noise of this run's references (quick runs cannot resolve 1 %)"
                )
            )

    for warning in sorted({w for row in results["equal_rmse"] for w in row["bridge_warnings"]}):
        notes.append(f"mitsuba bridge: {warning}")
    if "bvh" in chosen:
        log.info("BVH at scale ...")
        results["bvh"] = bvh_section(settings, variant, device)
    if "features" in chosen:
        log.info("effects on demand ...")
        results["features"] = features_section(scene, camera, settings, device)
        notes += effect_notes(results["features"])
    if "profile" in chosen:
        log.info("profile ...")
        results["profile"] = profile_section(scene, camera, settings, variant, device)

    note = (
        plot(results["curves"], results["equal_rmse"], out / "render_rmse_vs_time.png") if results["curves"] else None
    )
    if note:
        notes.append(note)
    report = run_report("render", settings, variant, notes, started, load_start, device, results)

    title = (
        f"# invrender bench render ({settings.mode}; Mitsuba {variant}; {camera.width}x{camera.height}, "
        f"room view {settings.view}; {report['seconds']:.0f} s)"
    )
    ran = [key for key in ("equal_rmse", "one_time", "curves", "bvh", "features", "profile") if results[key]]
    write_report(out, "render", title, report, TABLES, ran)
    return report


def _main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="helpers of `invrender bench render`")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("bvh-probe", help="one BVH size, measured in this process; prints one JSON line")
    p.add_argument("--triangles", type=int, required=True)
    p.add_argument("--mode", choices=["full", "quick"], default="full")
    p.add_argument("--width", type=int)
    p.add_argument("--height", type=int)
    p.add_argument("--variant")
    p.add_argument("--no-mitsuba", action="store_true")
    p.add_argument("--device")
    e = sub.add_parser("features-only", help="only the effects-on-demand table (no Mitsuba)")
    e.add_argument("--quick", action="store_true")
    e.add_argument("--out", default="docs/benchmarks")
    e.add_argument("--device")
    e.add_argument("--width", type=int)
    e.add_argument("--height", type=int)
    args = parser.parse_args(argv)
    if args.command == "features-only":
        logging.basicConfig(level=logging.INFO, format="%(message)s")
        run_effects(args.quick, args.out, args.device, args.width, args.height)
        return 0
    settings = QUICK if args.mode == "quick" else FULL
    settings = replace(
        settings,
        width=args.width or settings.width,
        height=args.height or settings.height,
        bvh_mitsuba=settings.bvh_mitsuba and not args.no_mitsuba,
    )
    quiet_pyopencl()
    result = bvh_probe(args.triangles, settings, args.device, args.variant)
    print_probe(PROBE_MARK, result)
    return 0


if __name__ == "__main__":
    sys.exit(_main())

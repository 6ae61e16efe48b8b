"""`invrender bench gradients`: one gradient pass of invrender's adjoint against Mitsuba 3's `prb`.

A gradient pass is what one optimiser step costs: the forward render of the current scene, the
L2 loss against a target image, and its gradient with respect to the 256 x 256 kd atlas.
Everything is measured on the synthetic room (``synthesize.room``, its view 2: floor, walls,
the table, the window with sky and sun, the ceiling panels), made Lambertian (ks = 0, which is
exactly Lambertian in our model, docs/renderer.md) because Mitsuba's ``prb`` differentiates its
native ``diffuse`` BSDF; the glossy table would need our Python BSDF plugin under AD, which
would measure the plugin, not Mitsuba. The room's atlas is 256 x 256: its kd *is* the texture.

- Start: kd = 0.5 on every texel where the room's kd is not 0 (the ceiling panels and the
  window openings keep kd = 0, so both renderers still see lights and holes there); the target
  image is invrender's render of the room with its own kd at ``target_spp`` (one image, used by
  both). Loss = mean over pixels and channels of (L - target)^2.
- invrender: ``Renderer.render_requests`` (forward) then ``adjoint.backward`` with the adjoint
  2 (L - target) / n and the backward seed of ``RenderRays`` (other samples than the forward:
  unbiased for the L2 gradient). Mitsuba: ``mi.render(scene, params, spp, seed)`` with the kd
  bitmap tracking gradients, the same loss in drjit, ``dr.backward``, the gradient read back
  (``prb`` replays each path in its backward pass; its primal and backward samples differ too).
  Same image size, spp (forward and backward), depth (Mitsuba max_depth = B + 1, no Russian
  roulette), target and start.

1. **Time to equal gradient error** for B = 3 and 10, as `bench render` does for images. The
   reference gradient is the inverse-variance weighted mean of both renderers' high-spp
   gradients (each the mean of many independent passes, in two halves whose difference gives
   its noise); their agreement is checked and printed (texel MSE between them over their noise;
   the derivative along kd, i.e. sum(kd * gradient), relative difference and its 1-sigma). Error
   = RMSE over the covered texels (start kd > 0) and channels of a pass's gradient against the
   reference, the reference's own noise subtracted. A ladder of spp per renderer, interleaved
   (A B, B A) in shuffled order, `repeats` passes per rung; time = median wall clock of a pass
   (gradient in numpy), each spp warmed up first.
   ratio = t_mitsuba / t_invrender at the lower error both ladders reach (> 1: invrender
   faster), interpolated log-log; beside it the ratio from a fit error = k / sqrt(spp),
   t = a + b spp, and from process CPU time. The forward and backward halves of a pass are
   timed separately at the top rung (the profile table), and each backward is also run alone,
   fed the converged forward image: the share of a pass's variance that is the backward's own.
   One-time costs are excluded and reported: invrender's HostScene.pack, upload and render
   kernel build, first pass (adjoint kernel build); Mitsuba's conversion, load_dict, first pass
   (JIT compilation or a drjit kernel-cache hit). Not in a pass either: uploading new
   maps (an optimiser's step), reported as its own row.
2. **Peak memory of a 65,536-ray, 10-bounce gradient pass**: a 256 x 256 camera at 1 spp, in a
   subprocess per renderer (and accumulation mode): RSS after setup (scene loaded; the adjoint
   kernel and Mitsuba's JIT come with the first pass), peak RSS growth during the first pass and
   during a second one (after ``dr.flush_malloc_cache()`` for Mitsuba, whose allocator keeps
   freed memory; glibc's mmap threshold fixed, PROBE_ENV), and the process's peak RSS. PoCL's
   device buffers live in host memory, so RSS sees them.
3. **What determinism costs**: ``accumulation="fixed"`` (64-bit fixed-point atomics, the same
   bytes for the same seed) against ``"buckets"`` (MILO's float copies by ray id): the same
   passes interleaved, backward time and whole-pass time, and how far the two gradients differ.
   Measured only if ``adjoint.backward`` takes ``accumulation`` (else said in the notes).

docs/benchmarks.md ("Gradients") has a full run and its reading.
"""

from __future__ import annotations

import argparse
import contextlib
import gc
import inspect
import logging
import math
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

from .harness import (
    PeakRSS,
    choose_variant,
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
    time_at_rmse,
    verdict,
    write_report,
)

log = logging.getLogger("invrender.bench")

ROOM_VIEW = 2  # as bench render: floor, walls, table, window, ceiling panels
PROBE_MARK = "GRADPROBE "
START_KD = 0.5
# glibc returns large freed blocks to the system only below its mmap threshold, which it raises
# as big blocks are freed: fixed, a pass's transient buffers show in RSS in every pass, not just
# in the first.
PROBE_ENV = {"MALLOC_MMAP_THRESHOLD_": "131072", "MALLOC_TRIM_THRESHOLD_": "131072"}


@dataclass(frozen=True)
class Settings:
    mode: str
    width: int = 128
    height: int = 96
    view: int = ROOM_VIEW
    bounces: tuple = (3, 10)
    ladder: tuple = (1, 2, 4, 8, 16, 32)
    repeats: int = 5
    ref_spp: int = 2048  # per renderer, as passes of ref_pass_spp in two halves
    ref_pass_spp: int = 64
    target_spp: int = 1024
    memory_side: int = 256  # memory_side^2 rays = 65,536
    memory_bounces: int = 10
    accumulation_spp: int = 16
    accumulation_repeats: int = 6


FULL = Settings("full", repeats=7)
QUICK = Settings(
    "quick",
    width=32,
    height=24,
    bounces=(3,),
    ladder=(1, 2, 4),
    repeats=2,
    ref_spp=64,
    ref_pass_spp=16,
    target_spp=16,
    memory_side=32,
    accumulation_spp=2,
    accumulation_repeats=2,
)


def has_accumulation() -> bool:
    """Whether adjoint.backward offers the bucketed float accumulation beside fixed point."""
    from ..render.adjoint import backward

    return "accumulation" in inspect.signature(backward).parameters


def is_ad_variant(variant: str) -> bool:
    return "_ad_" in variant


# ---------------------------------------------------------------------------------------------
# The scene: the room, Lambertian; the start (kd = 0.5 where kd > 0) and the target image
# ---------------------------------------------------------------------------------------------


def lambertian_room(width: int, height: int):
    """(true scene, start scene, covered texel mask (H, W)): the room with ks = 0; the start has
    kd = START_KD wherever the room's kd is not 0 (lights and window openings stay black)."""
    from ..scene.types import Maps, Scene

    scene, _ = room_scene(width, height)
    m = scene.maps
    true = Scene(scene.mesh, Maps(kd=m.kd, ks=np.zeros_like(m.ks), ka=m.ka, ke=m.ke, kw=m.kw, kg=m.kg), scene.cameras)
    covered = np.any(m.kd > 0, -1)
    start_kd = np.where(covered[..., None], np.float32(START_KD), np.zeros_like(m.kd))
    start = Scene(scene.mesh, Maps(kd=start_kd, ks=true.maps.ks, ka=m.ka, ke=m.ke, kw=m.kw, kg=m.kg), scene.cameras)
    return true, start, covered


def target_image(true_scene, camera, features, spp: int, device=None) -> np.ndarray:
    from ..render.renderer import Renderer

    quiet_pyopencl()
    return Renderer(true_scene, features, device).render(camera, spp, seed=987_654, aovs=False)["radiance"]


# ---------------------------------------------------------------------------------------------
# The two gradient passes behind one interface: gradient(spp) -> d loss / d kd, (H, W, 3)
# ---------------------------------------------------------------------------------------------


@contextlib.contextmanager
def _counting_adjoint_runs():
    """The wall time of each run of the adjoint kernel over all samples within one `backward`
    (the fixed-point mode runs again when a map's scale was off). Informational: wraps
    adjoint.py's private `_accumulate`; yields an empty list if that name is gone."""
    from ..render import adjoint

    original = getattr(adjoint, "_accumulate", None)
    if original is None:
        yield []
        return
    runs = []

    def counted(*args, **kwargs):
        wall = time.perf_counter()
        out = original(*args, **kwargs)
        runs.append(time.perf_counter() - wall)
        return out

    adjoint._accumulate = counted
    try:
        yield runs
    finally:
        adjoint._accumulate = original


class InvrenderGradient:
    name = "invrender"

    def __init__(self, scene, camera, features, target: np.ndarray, device=None, host=None):
        from ..render.renderer import Renderer, pixel_requests
        from ..render.scene_buffers import HostScene

        quiet_pyopencl()
        self.camera, self.one_time = camera, {}
        if host is None:
            host, self.one_time["pack_s"], _ = clock(HostScene.pack, scene.mesh, scene.maps)
        self.renderer, self.one_time["init_s"], _ = clock(Renderer, scene, features, device, host_scene=host)
        self.requests = pixel_requests(camera, 0, self.renderer.ray_offset(camera))
        self.target = np.asarray(target, np.float32).reshape(-1, 3)
        self._seed = next_seed_block()
        self.last = {}

    def gradient(self, spp: int, accumulation: str = "fixed") -> np.ndarray:
        from ..render.adjoint import backward, backward_seed

        self._seed += 1
        cameras = [self.camera]
        wall = time.perf_counter()
        radiance, _, _ = self.renderer.render_requests(cameras, self.requests, int(spp), self._seed)
        forward = time.perf_counter() - wall
        self.image = radiance.reshape(self.camera.height, self.camera.width, 3)
        adjoint = 2.0 * (radiance - self.target) / self.target.size  # d mean((L - T)^2) / dL
        options = {"accumulation": accumulation} if accumulation != "fixed" else {}
        with _counting_adjoint_runs() as runs:
            grads = backward(
                self.renderer,
                cameras,
                self.requests,
                adjoint,
                int(spp),
                backward_seed(self._seed),
                maps=("kd",),  # what prb differentiates: the kd bitmap alone has gradients enabled
                **options,
            )
        self.last = {
            "forward_s": forward,
            "backward_s": time.perf_counter() - wall - forward,
            "adjoint_runs": len(runs) or None,
            "last_run_s": runs[-1] if runs else None,
        }
        return np.asarray(grads["kd"], np.float64)

    def backward_alone(self, spp: int, image: np.ndarray) -> np.ndarray:
        """The backward half with the adjoint of a converged forward image: its noise alone."""
        from ..render.adjoint import backward, backward_seed

        self._seed += 1
        adjoint = 2.0 * (np.asarray(image, np.float32).reshape(-1, 3) - self.target) / self.target.size
        grads = backward(
            self.renderer, [self.camera], self.requests, adjoint, int(spp), backward_seed(self._seed), maps=("kd",)
        )
        return np.asarray(grads["kd"], np.float64)

    def warm_up(self, spp: int = 1):
        _, self.one_time["first_pass_s"], _ = clock(self.gradient, spp)

    def new_maps(self, maps):
        """An optimiser's step: new maps to the device (the BVH stays)."""
        self.renderer.set_maps(maps)


class MitsubaGradient:
    name = "mitsuba"

    def __init__(self, scene, camera, bounces: int, variant: str, target: np.ndarray, roulette_depth: int = 0):
        from .. import mitsuba as bridge  # noqa: I001 - first: it points drjit at a usable libLLVM
        import drjit as dr
        import mitsuba as mi

        self.mi, self.dr, self.one_time = mi, dr, {}
        scene_dict, self.one_time["convert_s"], _ = clock(
            bridge.scene_to_mitsuba_diffuse,
            scene,
            camera,
            bounces,
            1,
            variant,
            integrator=bridge.prb_integrator(bounces, roulette_depth),
        )
        self.scene, self.one_time["load_s"], _ = clock(mi.load_dict, scene_dict, parallel=False)
        self.params = mi.traverse(self.scene)
        self.key = bridge.kd_parameter(self.params)
        dr.enable_grad(self.params[self.key])
        self.params.update()
        self.target = mi.TensorXf(np.ascontiguousarray(target, np.float32))
        self._seed = next_seed_block()
        self.warmed: dict[int, float] = {}
        self.last = {}

    def gradient(self, spp: int) -> np.ndarray:
        mi, dr = self.mi, self.dr
        self._seed += 1
        wall = time.perf_counter()
        image = mi.render(self.scene, self.params, spp=int(spp), seed=self._seed % 2**32)
        dr.eval(image)
        dr.sync_thread()  # drjit's LLVM backend launches asynchronously
        forward = time.perf_counter() - wall
        self.image = np.array(image, np.float32)
        dr.backward(dr.mean(dr.square(image - self.target), axis=None))
        grad = np.array(dr.grad(self.params[self.key]), np.float64)
        dr.set_grad(self.params[self.key], 0.0)
        self.last = {"forward_s": forward, "backward_s": time.perf_counter() - wall - forward}
        return grad

    def backward_alone(self, spp: int, image: np.ndarray) -> np.ndarray:
        """prb's backward (`render_backward`: its own primal pass, then the replay) with the
        adjoint image of a converged forward image: its noise alone."""
        mi, dr = self.mi, self.dr
        self._seed += 1
        adjoint = 2.0 * (np.asarray(image, np.float32) - np.array(self.target, np.float32)) / image.size
        self.scene.integrator().render_backward(
            self.scene, self.params, mi.TensorXf(adjoint.astype(np.float32)), seed=self._seed % 2**32, spp=int(spp)
        )
        grad = np.array(dr.grad(self.params[self.key]), np.float64)
        dr.set_grad(self.params[self.key], 0.0)
        return grad

    def warm_up(self, spp: int = 1):
        """The first pass at an spp compiles its kernels (or finds them in drjit's cache)."""
        if spp not in self.warmed:
            self.warmed[spp] = clock(self.gradient, spp)[1]
        self.one_time["first_pass_s"] = self.warmed.get(1, next(iter(self.warmed.values())))

    def new_maps(self, maps):
        """An optimiser's step: a new kd bitmap (gradient tracking kept)."""
        mi, dr = self.mi, self.dr
        self.params[self.key] = mi.TensorXf(np.ascontiguousarray(maps.kd, np.float32))
        dr.enable_grad(self.params[self.key])
        self.params.update()


# ---------------------------------------------------------------------------------------------
# 1. Time to equal gradient error
# ---------------------------------------------------------------------------------------------


def _median_or_none(values):
    values = [v for v in values if v is not None]
    return median(values) if values else None


def _mean_or_none(values):
    values = [v for v in values if v is not None]
    return float(np.mean(values)) if values else None


def reference(runners, settings: Settings, covered: np.ndarray, desc: str):
    """Per renderer: the mean of ref_spp / ref_pass_spp passes, as two halves -> its converged
    gradient, noise MSE (per covered texel and channel), and the derivative along the start kd
    with its noise. Then the inverse-variance weighted mean of both, and its noise MSE."""
    passes = max(2, settings.ref_spp // settings.ref_pass_spp)
    converged = {}
    for runner in runners:
        halves, walls, images = [[], []], [], []
        for k in tqdm(range(passes), desc=f"{desc} {runner.name}", unit="pass", leave=False):
            grad, wall, _ = clock(runner.gradient, settings.ref_pass_spp)
            halves[k % 2].append(grad[covered])
            walls.append(wall)
            images.append(runner.image.astype(np.float64))
        a, b = (np.mean(h, 0) for h in halves)
        dirs = [np.sum(g) * START_KD for h in halves for g in h]  # sum(kd * grad), kd = START_KD on covered texels
        converged[runner.name] = {
            "grad": (a + b) / 2,
            "noise_mse": max(float(np.mean((a - b) ** 2) / 4.0), 1e-300),
            "directional": float(np.mean(dirs)),
            "directional_var": float(np.var(dirs, ddof=1) / len(dirs)),
            "spp": passes * settings.ref_pass_spp,
            "seconds": float(np.sum(walls)),
            "image": np.mean(images, 0),
            "image_mean": float(np.mean(images)),
            "image_mean_var": float((np.mean(images[0::2]) - np.mean(images[1::2])) ** 2 / 4.0),
        }
    weights = {name: 1.0 / c["noise_mse"] for name, c in converged.items()}
    total = sum(weights.values())
    ref = sum(weights[name] * c["grad"] for name, c in converged.items()) / total
    return ref, 1.0 / total, converged


def reference_agreement(converged: dict) -> dict:
    """How the two converged gradients differ: texel MSE over the MSE their noise explains
    (1 = no texel-level bias), excess RMSE relative to the gradient's RMS, and the relative
    difference of the derivative along kd with its 1-sigma; and the mean of the two converged
    forward images (the L2 gradient's (L - target) turns a small difference in L into a larger
    one in the gradient)."""
    a, b = converged["invrender"], converged["mitsuba"]
    mse = float(np.mean((a["grad"] - b["grad"]) ** 2))
    rms = math.sqrt(float(np.mean(b["grad"] ** 2)))
    diff = (a["directional"] - b["directional"]) / abs(b["directional"])
    sigma = math.sqrt(a["directional_var"] + b["directional_var"]) / abs(b["directional"])
    image_diff = (a["image_mean"] - b["image_mean"]) / b["image_mean"]
    image_sigma = math.sqrt(a["image_mean_var"] + b["image_mean_var"]) / b["image_mean"]
    return {
        "mean_rel_diff": diff,
        "mean_rel_sigma": sigma,
        "image_rel_diff": image_diff,
        "image_rel_sigma": image_sigma,
        "texel_mse_over_noise": mse / (a["noise_mse"] + b["noise_mse"]),
        "excess_rel_rmse": math.sqrt(max(0.0, mse - a["noise_mse"] - b["noise_mse"])) / rms,
    }


def equal_error(true, start, covered, camera, bounces: int, settings: Settings, variant: str, device=None):
    from ..render.analysis import analyse

    features = analyse(start, device=device).with_bounces(bounces)
    target, target_s, _ = clock(target_image, true, camera, features, settings.target_spp, device)
    inv = InvrenderGradient(start, camera, features, target, device)
    inv.warm_up()
    runners = [inv]
    if is_ad_variant(variant):
        mit = MitsubaGradient(start, camera, bounces, variant, target, features.roulette_depth)
        runners.append(mit)
    for runner in runners:
        for spp in sorted({*settings.ladder, settings.ref_pass_spp}):
            runner.warm_up(spp)

    ref, ref_noise, converged = reference(runners, settings, covered, f"reference B={bounces}")
    ref_rms = math.sqrt(float(np.mean(ref**2)))
    forward_image = np.mean([c["image"] for c in converged.values()], 0)  # the converged forward render

    records = []
    jobs = [(spp, rep) for spp in settings.ladder for rep in range(settings.repeats)]
    jobs = [jobs[i] for i in np.random.default_rng(0).permutation(len(jobs))]  # as bench render
    for spp, rep in tqdm(jobs, desc=f"ladder B={bounces}", unit="pass", leave=False):
        for runner in runners if rep % 2 == 0 else runners[::-1]:
            grad, wall, cpu = clock(runner.gradient, spp)
            mse = float(np.mean((grad[covered] - ref) ** 2))
            records.append({"renderer": runner.name, "spp": spp, "wall": wall, "cpu": cpu, "mse": mse, **runner.last})

    # The backward half alone, fed the converged forward image: how much of a pass's variance is
    # the backward's own (the rest comes from the forward's noise in L - target).
    top_spp = settings.ladder[-1]
    alone = {runner.name: [] for runner in runners}
    for rep in tqdm(range(settings.repeats), desc=f"backward alone B={bounces}", leave=False):
        for runner in runners if rep % 2 == 0 else runners[::-1]:
            grad = runner.backward_alone(top_spp, forward_image)
            alone[runner.name].append(float(np.mean((grad[covered] - ref) ** 2)))

    pixels = camera.width * camera.height
    curves, summary = [], {}
    for runner in runners:
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
                    "forward_s": median([r["forward_s"] for r in mine]),
                    "backward_s": median([r["backward_s"] for r in mine]),
                    "adjoint_runs": _mean_or_none([r.get("adjoint_runs") for r in mine]),
                    "rmse": math.sqrt(mse),
                    "rmse_raw": math.sqrt(mse_raw),
                    "rel_rmse": math.sqrt(mse) / ref_rms,
                    "repeats": len(mine),
                }
            )
        curves += rows
        top = rows[-1]
        summary[runner.name] = {
            "times": [r["wall_s"] for r in rows],
            "rmses": [r["rmse"] for r in rows],
            "cpu_times": [r["cpu_s"] for r in rows],
            "top": top,
            "samples_per_s": pixels * top["spp"] / top["wall_s"],
            "cpu_per_wall": top["cpu_s"] / top["wall_s"],
            "var_per_sample": top["rmse"] ** 2 * top["spp"],
            "backward_var_per_sample": max(float(np.mean(alone[runner.name])) - ref_noise, 0.0) * top_spp,
        }
    s_inv = summary["invrender"]
    row = {
        "section": "equal_error",
        "bounces": bounces,
        "mitsuba_variant": variant,
        "width": camera.width,
        "height": camera.height,
        "ref_rms": ref_rms,
        "ref_noise_rel_rmse": math.sqrt(ref_noise) / ref_rms,
        "samples_per_s_invrender": s_inv["samples_per_s"],
        "var_per_sample_invrender": s_inv["var_per_sample"],
        "cpu_per_wall_invrender": s_inv["cpu_per_wall"],
        "features": asdict(features),
        "ref_spp": {name: c["spp"] for name, c in converged.items()},
        "target_spp": settings.target_spp,
        "target_render_s": target_s,
        # How large L - target is against L: a difference d in L is d / this in the L2 gradient.
        "residual_rel": float(np.mean(np.abs(forward_image - target)) / np.mean(forward_image)),
    }
    profile = [
        {
            "section": "profile",
            "bounces": bounces,
            "renderer": name,
            "spp": s["top"]["spp"],
            "pass_s": s["top"]["wall_s"],
            "forward_s": s["top"]["forward_s"],
            "backward_s": s["top"]["backward_s"],
            "backward_over_forward": s["top"]["backward_s"] / s["top"]["forward_s"],
            "adjoint_runs": s["top"].get("adjoint_runs"),
            "samples_per_s": s["samples_per_s"],
            "cpu_per_wall": s["cpu_per_wall"],
            "var_per_sample": s["var_per_sample"],
            "backward_var_per_sample": s["backward_var_per_sample"],
            "backward_var_share": s["backward_var_per_sample"] / s["var_per_sample"],
        }
        for name, s in summary.items()
    ]
    if "mitsuba" in summary:
        s_mit = summary["mitsuba"]
        target_rmse = max(s["rmses"][-1] for s in summary.values())
        t_inv, extra_inv = time_at_rmse(s_inv["times"], s_inv["rmses"], target_rmse)
        t_mit, extra_mit = time_at_rmse(s_mit["times"], s_mit["rmses"], target_rmse)
        cpu_inv, _ = time_at_rmse(s_inv["cpu_times"], s_inv["rmses"], target_rmse)
        cpu_mit, _ = time_at_rmse(s_mit["cpu_times"], s_mit["rmses"], target_rmse)
        model = {name: fit_model(settings.ladder, summary[name]["times"], summary[name]["rmses"]) for name in summary}
        check = reference_agreement(converged)
        row.update(
            {
                "target_rmse": target_rmse,
                "target_rel_rmse": target_rmse / ref_rms,
                "t_invrender_s": t_inv,
                "t_mitsuba_s": t_mit,
                "ratio": t_mit / t_inv,
                "ratio_fit": model_time(model["mitsuba"], target_rmse) / model_time(model["invrender"], target_rmse),
                "ratio_cpu": cpu_mit / cpu_inv,
                "extrapolated": bool(extra_inv or extra_mit),
                "fit_invrender": model["invrender"],
                "fit_mitsuba": model["mitsuba"],
                "samples_per_s_mitsuba": s_mit["samples_per_s"],
                "speed_ratio": s_inv["samples_per_s"] / s_mit["samples_per_s"],
                "var_per_sample_mitsuba": s_mit["var_per_sample"],
                "variance_ratio": s_mit["var_per_sample"] / s_inv["var_per_sample"],
                "cpu_per_wall_mitsuba": s_mit["cpu_per_wall"],
                **check,
                "agreement": verdict(check, min(c["spp"] for c in converged.values())),
            }
        )
        for p in profile:
            other = [q for q in profile if q is not p][0]
            p["pass_vs_other"] = p["pass_s"] / other["pass_s"]
            p["var_vs_other"] = p["var_per_sample"] / other["var_per_sample"]
            p["backward_var_vs_other"] = p["backward_var_per_sample"] / max(other["backward_var_per_sample"], 1e-300)

    one_steady = {
        r.name: median([x["wall"] for x in records if x["renderer"] == r.name and x["spp"] == settings.ladder[0]])
        for r in runners
    }
    one_time = [
        {
            "section": "one_time",
            "bounces": bounces,
            "renderer": "invrender",
            "scene_s": inv.one_time["pack_s"],
            "scene_what": "HostScene.pack (BVH, emitter BVH, tables)",
            "setup_s": inv.one_time["init_s"],
            "setup_what": "upload + render kernel build",
            "first_pass_s": inv.one_time["first_pass_s"],
            "first_what": "+ adjoint kernel build",
            "steady_pass_s": one_steady["invrender"],
            "maps_step_s": median([clock(inv.new_maps, start.maps)[1] for _ in range(3)]),
            "maps_what": "Renderer.set_maps",
        }
    ]
    if len(runners) > 1:
        mit = runners[1]
        one_time.append(
            {
                "section": "one_time",
                "bounces": bounces,
                "renderer": f"mitsuba {variant} prb",
                "scene_s": mit.one_time["convert_s"],
                "scene_what": "scene_to_mitsuba_diffuse (our bridge)",
                "setup_s": mit.one_time["load_s"],
                "setup_what": "mi.load_dict (plugins, BVH)",
                "first_pass_s": mit.one_time["first_pass_s"],
                "first_what": "JIT; first pass at each spp: "
                + ", ".join(f"{k}: {v:.2f}" for k, v in sorted(mit.warmed.items())),
                "steady_pass_s": one_steady["mitsuba"],
                "maps_step_s": median([clock(mit.new_maps, start.maps)[1] for _ in range(3)]),
                "maps_what": "params[kd] = ...; params.update()",
            }
        )
    return row, curves, one_time, profile


# ---------------------------------------------------------------------------------------------
# 2. Peak memory of a 65,536-ray, 10-bounce gradient pass (one subprocess each)
# ---------------------------------------------------------------------------------------------


def _rss_mb() -> float:
    import psutil

    return psutil.Process().memory_info().rss / 2**20


def memory_probe(renderer: str, side: int, bounces: int, accumulation: str, variant: str, device=None) -> dict:
    """Runs in its own process (`python -m invrender.bench.gradients memory-probe`): one pass of
    side x side rays at 1 spp, B bounces, L2 loss against a black target."""
    from ..render.analysis import analyse

    _, start, _ = lambertian_room(side, side)
    camera = start.cameras[ROOM_VIEW]
    target = np.zeros((side, side, 3), np.float32)
    features = analyse(start, device=device).with_bounces(bounces)
    if renderer == "invrender":
        runner = InvrenderGradient(start, camera, features, target, device)
        run = lambda: runner.gradient(1, accumulation)  # noqa: E731
        flush = lambda: None  # noqa: E731
    else:
        import drjit as dr

        runner = MitsubaGradient(start, camera, bounces, variant, target, features.roulette_depth)
        run = lambda: runner.gradient(1)  # noqa: E731
        flush = dr.flush_malloc_cache
    gc.collect()
    setup_mb = _rss_mb()
    with PeakRSS() as first:
        _, first_s, _ = clock(run)
    gc.collect()
    flush()
    before_second = _rss_mb()
    with PeakRSS() as second:
        _, second_s, second_cpu = clock(run)
    return {
        "section": "memory",
        "renderer": renderer if renderer == "invrender" else f"mitsuba {variant} prb",
        "accumulation": accumulation if renderer == "invrender" else "-",
        "rays": side * side,
        "bounces": bounces,
        "rss_after_setup_mb": setup_mb,
        "first_pass_growth_mb": first.growth / 2**20,
        "rss_before_second_mb": before_second,
        "pass_growth_mb": second.growth / 2**20,
        # Polled, not ru_maxrss: in these children it read the parent's high-water mark.
        "peak_rss_mb": max(setup_mb, first.peak / 2**20, second.peak / 2**20),
        "first_pass_s": first_s,
        "pass_s": second_s,
        "pass_cpu_s": second_cpu,
    }


def memory_section(settings: Settings, variant: str, accumulations, device=None) -> list[dict]:
    cases = [("invrender", a) for a in accumulations]
    if is_ad_variant(variant):
        cases.append(("mitsuba", "-"))
    rows = []
    for renderer, accumulation in tqdm(cases, desc="memory", unit="probe", leave=False):
        args = ["memory-probe", "--renderer", renderer, "--side", settings.memory_side]
        args += ["--bounces", settings.memory_bounces, "--accumulation", accumulation, "--variant", variant]
        if device:
            args += ["--device", device]
        what = f"memory probe ({renderer}, {accumulation})"
        rows.append(run_probe("invrender.bench.gradients", args, PROBE_MARK, what, env=PROBE_ENV))
    return rows


# ---------------------------------------------------------------------------------------------
# 3. What determinism costs: fixed-point against bucketed float accumulation
# ---------------------------------------------------------------------------------------------


def accumulation_section(start, camera, settings: Settings, device=None) -> list[dict]:
    from ..render.analysis import analyse

    rows = []
    target = np.zeros((camera.height, camera.width, 3), np.float32)
    for bounces in settings.bounces:
        features = analyse(start, device=device).with_bounces(bounces)
        runner = InvrenderGradient(start, camera, features, target, device)
        for mode in ("fixed", "buckets"):  # kernel builds and first launches out of the timing
            runner.gradient(settings.accumulation_spp, mode)
        times = {"fixed": [], "buckets": []}
        runs = {"fixed": [], "buckets": []}
        last_run = {"fixed": [], "buckets": []}
        diffs = []
        for rep in tqdm(range(settings.accumulation_repeats), desc=f"accumulation B={bounces}", leave=False):
            pair = {}
            for mode in ("fixed", "buckets") if rep % 2 == 0 else ("buckets", "fixed"):
                seed = runner._seed
                grad, wall, _ = clock(runner.gradient, settings.accumulation_spp, mode)
                runner._seed = seed  # both modes trace the same samples: their sums differ by rounding only
                times[mode].append((wall, runner.last["backward_s"]))
                runs[mode].append(runner.last["adjoint_runs"])
                last_run[mode].append(runner.last["last_run_s"])
                pair[mode] = grad
            runner._seed += 1
            scale = float(np.abs(pair["fixed"]).max())
            diffs.append(float(np.abs(pair["buckets"] - pair["fixed"]).max()) / max(scale, 1e-300))
        med = {mode: (median([t[0] for t in v]), median([t[1] for t in v])) for mode, v in times.items()}
        rows.append(
            {
                "section": "accumulation",
                "bounces": bounces,
                "rays": camera.width * camera.height,
                "spp": settings.accumulation_spp,
                "repeats": settings.accumulation_repeats,
                "backward_fixed_s": med["fixed"][1],
                "backward_buckets_s": med["buckets"][1],
                "backward_ratio": med["fixed"][1] / med["buckets"][1],
                "pass_fixed_s": med["fixed"][0],
                "pass_buckets_s": med["buckets"][0],
                "pass_ratio": med["fixed"][0] / med["buckets"][0],
                "max_rel_diff": max(diffs),
                "adjoint_runs_fixed": _mean_or_none(runs["fixed"]),
                # One run of each, the fixed one at the scales its first run chose: what the
                # accumulation itself costs, without the fixed mode's scale-finding run.
                "run_fixed_s": _median_or_none(last_run["fixed"]),
                "run_buckets_s": _median_or_none(last_run["buckets"]),
            }
        )
        row = rows[-1]
        if row["run_fixed_s"] and row["run_buckets_s"]:
            row["run_ratio"] = row["run_fixed_s"] / row["run_buckets_s"]
    return rows


# ---------------------------------------------------------------------------------------------
# Output
# ---------------------------------------------------------------------------------------------

TABLES = {
    "equal_error": (
        "Time to equal gradient error (wall clock, median of repeats; ratio = t_mitsuba / t_invrender, "
        "> 1: invrender faster)",
        [
            ("bounces", "B", "d"),
            ("width", "W", "d"),
            ("height", "H", "d"),
            ("target_rel_rmse", "target rel. error", ".3f"),
            ("t_invrender_s", "t inv [s]", ".3g"),
            ("t_mitsuba_s", "t mi [s]", ".3g"),
            ("ratio", "ratio", ".3f"),
            ("ratio_fit", "ratio (fit)", ".3f"),
            ("ratio_cpu", "ratio (CPU time)", ".3f"),
            ("speed_ratio", "samples/s inv/mi", ".3f"),
            ("variance_ratio", "var/sample mi/inv", ".3f"),
            ("ref_noise_rel_rmse", "ref noise (rel.)", ".3f"),
            ("mean_rel_diff", "d/dkd along kd: rel diff", "+.2%"),
            ("mean_rel_sigma", "(1 sigma)", ".2%"),
            ("agreement", "gradients", "s"),
            ("texel_mse_over_noise", "texel MSE / noise", ".2f"),
            ("image_rel_diff", "forward images: rel diff", "+.2%"),
            ("image_rel_sigma", "(1 sigma) ", ".2%"),
        ],
    ),
    "one_time": (
        "One-time costs, excluded from the pass times above [s]",
        [
            ("bounces", "B", "d"),
            ("renderer", "renderer", "s"),
            ("scene_s", "scene", ".3f"),
            ("scene_what", "= what", "s"),
            ("setup_s", "setup", ".3f"),
            ("setup_what", "= what", "s"),
            ("first_pass_s", "first pass (1 spp)", ".3f"),
            ("first_what", "= what", "s"),
            ("steady_pass_s", "later 1-spp pass", ".4f"),
            ("maps_step_s", "new maps (a step)", ".4f"),
            ("maps_what", "= what", "s"),
        ],
    ),
    "curves": (
        "Gradient error against time (the ladders; error with the reference's noise removed, "
        "relative to the reference's RMS)",
        [
            ("bounces", "B", "d"),
            ("renderer", "renderer", "s"),
            ("spp", "spp", "d"),
            ("wall_s", "pass [s]", ".4f"),
            ("wall_min_s", "min", ".4f"),
            ("wall_max_s", "max", ".4f"),
            ("cpu_s", "cpu [s]", ".4f"),
            ("forward_s", "forward [s]", ".4f"),
            ("backward_s", "backward [s]", ".4f"),
            ("adjoint_runs", "adjoint runs", ".1f"),
            ("rel_rmse", "rel. error", ".4g"),
        ],
    ),
    "profile": (
        "A pass at the top rung: forward and backward halves (median of repeats)",
        [
            ("bounces", "B", "d"),
            ("renderer", "renderer", "s"),
            ("spp", "spp", "d"),
            ("pass_s", "pass [s]", ".3f"),
            ("forward_s", "forward [s]", ".3f"),
            ("backward_s", "backward [s]", ".3f"),
            ("backward_over_forward", "backward / forward", ".2f"),
            ("adjoint_runs", "adjoint runs", ".2f"),
            ("pass_vs_other", "pass / other's pass", ".2f"),
            ("samples_per_s", "samples/s", ".3g"),
            ("cpu_per_wall", "CPU / wall", ".2f"),
            ("var_per_sample", "var/sample", ".3g"),
            ("var_vs_other", "var / other's", ".2f"),
            ("backward_var_share", "of it: backward alone", ".0%"),
            ("backward_var_vs_other", "backward var / other's", ".2f"),
        ],
    ),
    "memory": (
        "Peak memory of one gradient pass (1 spp), each renderer in its own process [MB]",
        [
            ("renderer", "renderer", "s"),
            ("accumulation", "accumulation", "s"),
            ("rays", "rays", "d"),
            ("bounces", "B", "d"),
            ("rss_after_setup_mb", "RSS after setup", ".0f"),
            ("first_pass_growth_mb", "growth, first pass", ".1f"),
            ("pass_growth_mb", "growth, second pass", ".1f"),
            ("peak_rss_mb", "process peak RSS", ".0f"),
            ("first_pass_s", "first pass [s]", ".3f"),
            ("pass_s", "second pass [s]", ".3f"),
        ],
    ),
    "accumulation": (
        "What determinism costs: fixed-point against bucketed float accumulation (median of interleaved passes)",
        [
            ("bounces", "B", "d"),
            ("rays", "rays", "d"),
            ("spp", "spp", "d"),
            ("backward_fixed_s", "backward fixed [s]", ".4f"),
            ("backward_buckets_s", "backward buckets [s]", ".4f"),
            ("backward_ratio", "fixed / buckets", ".3f"),
            ("pass_fixed_s", "pass fixed [s]", ".4f"),
            ("pass_buckets_s", "pass buckets [s]", ".4f"),
            ("pass_ratio", "pass fixed / buckets", ".3f"),
            ("adjoint_runs_fixed", "adjoint runs (fixed)", ".2f"),
            ("run_fixed_s", "one run fixed [s]", ".4f"),
            ("run_buckets_s", "one run buckets [s]", ".4f"),
            ("run_ratio", "one run fixed / buckets", ".3f"),
            ("max_rel_diff", "max |diff| / max |grad|", ".1e"),
        ],
    ),
}
SECTIONS = ("equal_error", "one_time", "curves", "profile", "memory", "accumulation")


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None) -> dict:
    quiet_pyopencl()
    settings = QUICK if quick else FULL
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    notes = []
    variant, why = choose_variant()
    if why:
        notes.append(why)
    if not is_ad_variant(variant):
        notes.append(
            f"Mitsuba {variant} has no automatic differentiation (prb needs an *_ad_* variant): "
            "invrender's gradient passes are measured alone, without a peer"
        )
        log.warning("%s", notes[-1])
    accumulations = ("fixed", "buckets") if has_accumulation() else ("fixed",)
    if len(accumulations) == 1:
        notes.append("adjoint.backward has no `accumulation` option yet: only the fixed-point mode is measured")
    started = time.time()
    load_start = os.getloadavg()
    log.info("bench gradients (%s): Mitsuba %s, out %s", settings.mode, variant, out)

    true, start, covered = lambertian_room(settings.width, settings.height)
    camera = start.cameras[settings.view]
    results = {key: [] for key in SECTIONS}
    for bounces in tqdm(settings.bounces, desc="equal gradient error", unit="B"):
        row, curves, one_time, profile = equal_error(true, start, covered, camera, bounces, settings, variant, device)
        results["equal_error"].append(row)
        results["curves"] += curves
        results["one_time"] += one_time
        results["profile"] += profile
        if row.get("agreement") not in (None, "agree", "not checked"):
            notes.append(
                f"B={bounces}: the converged gradients of invrender and Mitsuba differ along kd by "
                f"{100 * row['mean_rel_diff']:+.2f} % (1 sigma {100 * row['mean_rel_sigma']:.2f} %): "
                + ("a bug, not noise" if row["agreement"] == "DIFFER" else "within the noise of this run")
            )
    log.info("memory of a %d-ray, %d-bounce pass ...", settings.memory_side**2, settings.memory_bounces)
    results["memory"] = memory_section(settings, variant, accumulations, device)
    if len(accumulations) > 1:
        log.info("fixed-point against bucketed accumulation ...")
        results["accumulation"] = accumulation_section(start, camera, settings, device)

    if len(results["curves"]) and is_ad_variant(variant):
        note = plot(
            results["curves"],
            results["equal_error"],
            out / "gradients_error_vs_time.png",
            xlabel="wall time per gradient pass [s]",
            ylabel="gradient RMSE vs reference",
            curves_csv="gradients_curves.csv",
        )
        if note:
            notes.append(note)
    report = run_report(
        "gradients", settings, variant, notes, started, load_start, device, results, accumulations=list(accumulations)
    )

    title = (
        f"# invrender bench gradients ({settings.mode}; Mitsuba {variant} prb; {camera.width}x{camera.height}, "
        f"room view {settings.view}, d loss / d kd of a {covered.shape[1]}x{covered.shape[0]} atlas; "
        f"{report['seconds']:.0f} s)"
    )
    write_report(out, "gradients", title, report, TABLES, SECTIONS)
    return report


def _main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="helpers of `invrender bench gradients`")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("memory-probe", help="one gradient pass measured in this process; prints one JSON line")
    p.add_argument("--renderer", choices=["invrender", "mitsuba"], required=True)
    p.add_argument("--side", type=int, required=True, help="camera side: side^2 rays at 1 spp")
    p.add_argument("--bounces", type=int, required=True)
    p.add_argument("--accumulation", default="fixed")
    p.add_argument("--variant", default="llvm_ad_rgb")
    p.add_argument("--device")
    args = parser.parse_args(argv)
    quiet_pyopencl()
    result = memory_probe(args.renderer, args.side, args.bounces, args.accumulation, args.variant, args.device)
    print_probe(PROBE_MARK, result)
    return 0


if __name__ == "__main__":
    sys.exit(_main())

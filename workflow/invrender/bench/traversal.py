"""`invrender bench traversal`: closest-hit throughput of the BVH traversal alone.

On the benchmark room (view 2) as it is and subdivided to ~214 k triangles: camera rays (jittered,
``spp`` per pixel) and one cosine-sampled bounce from each hit, as a B = 1 render traces them,
are traced by kernels/traversal.cl's ``closest_hits`` without shading; rays/s = rays / median
wall time of a launch (and per CPU second: less sensitive to other jobs). Beside it: nodes and
triangles visited per ray (a ``-D BVH_STATS`` build), and whole B = 1 renders of ours (closest
hits only, as bench render's "bare" one-bounce row) and of Mitsuba 3 (llvm_ad_rgb), interleaved.

Each size is measured in its own process. ``python -m invrender.bench.traversal run --baseline
DIR`` alternates those processes between this source tree and another one (DIR holds its
``workflow/`` and ``kernels/``; this file and traversal.cl are copied into it, so that both are
measured the same way), round by round (A B, B A, ...) since the machine is shared, gives the
speed-ups as medians of the per-round ratios, and counts the rays for which the two trees found
different triangles or distances.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
from dataclasses import asdict, dataclass, replace
from pathlib import Path

import numpy as np

from .harness import choose_variant, clock, median, quiet_pyopencl, room_scene, run_report, start_run, write_report

MARK = "TRAVERSAL "
TREE = Path(__file__).resolve().parents[3]  # the source tree this file belongs to


@dataclass(frozen=True)
class Settings:
    mode: str
    sizes: tuple = (0, 200_000)  # triangles (0: the room as it is)
    width: int = 256
    height: int = 192
    spp: int = 4  # camera rays per pixel
    repeats: int = 7  # launches timed per process
    rounds: int = 3  # processes per size and tree
    view: int = 2
    mitsuba: bool = True  # Mitsuba's B = 1 render beside ours (llvm_ad_rgb only)


FULL = Settings("full")
QUICK = Settings("quick", sizes=(0,), width=64, height=48, spp=1, repeats=2, rounds=1, mitsuba=False)


def probe(triangles: int, settings: Settings, device=None, hits_path=None) -> dict:
    """One size in this process: rays/s of closest_hits, visits per ray, and a B = 1 render."""
    import pyopencl as cl

    from ..render.device import context_and_queue
    from ..render.features import Features
    from ..render.program import build_program
    from ..render.scene_buffers import HostScene, pack_cameras
    from ..scene.types import Scene
    from .render import InvrenderRunner, MitsubaRunner, subdivide_mesh, subdivisions_for

    base, _ = room_scene(settings.width, settings.height)
    n = subdivisions_for(len(base.mesh.faces), triangles) if triangles else 1
    scene = Scene(subdivide_mesh(base.mesh, n), base.maps, base.cameras)
    camera = scene.cameras[settings.view]
    host, pack_s, _ = clock(HostScene.pack, scene.mesh, scene.maps)
    context, queue = context_and_queue(device)
    args = host.upload(context, 0.25, 0.25)
    program = build_program(context, "traversal.cl")
    buffer = lambda a: cl.Buffer(context, cl.mem_flags.READ_WRITE | cl.mem_flags.COPY_HOST_PTR, hostbuf=a)
    empty = lambda count: np.zeros((count, 4), np.float32)

    def run(prog, name, count, *kernel_args):
        getattr(prog, name)(queue, (count,), None, *kernel_args)
        queue.finish()

    def trace(prog, o, d, *extra):
        out = empty(len(o))
        o_buf, d_buf, out_buf = buffer(o), buffer(d), buffer(out)
        extra_bufs = [buffer(e) for e in extra]
        run(prog, "closest_hits", len(o), *args, o_buf, d_buf, out_buf, *extra_bufs)
        cl.enqueue_copy(queue, out, out_buf)
        for e, b in zip(extra, extra_bufs):
            cl.enqueue_copy(queue, e, b)
        times = []
        if prog is program:
            for _ in range(settings.repeats):
                times.append(clock(run, prog, "closest_hits", len(o), *args, o_buf, d_buf, out_buf)[1:])
        return out, np.array(times).reshape(-1, 2)

    count = camera.width * camera.height * settings.spp
    o1, d1 = empty(count), empty(count)
    cams, o_buf, d_buf = buffer(pack_cameras([camera])), buffer(o1), buffer(d1)
    run(program, "camera_rays", count, cams, np.uint64(1), o_buf, d_buf)
    cl.enqueue_copy(queue, o1, o_buf)
    cl.enqueue_copy(queue, d1, d_buf)
    h1, t1 = trace(program, o1, d1)
    o2, d2 = empty(count), empty(count)
    o2_buf, d2_buf = buffer(o2), buffer(d2)
    run(program, "bounce_rays", count, *args, o_buf, d_buf, buffer(h1), np.uint64(2), o2_buf, d2_buf)
    cl.enqueue_copy(queue, o2, o2_buf)
    cl.enqueue_copy(queue, d2, d2_buf)
    keep = np.any(d2 != 0, axis=1)
    o2, d2 = o2[keep], d2[keep]
    h2, t2 = trace(program, o2, d2)
    # What sorting the bounce rays would give a wavefront renderer (the sort itself not timed).
    order = direction_order(o2, d2)
    _, t2_sorted = trace(program, o2[order], d2[order])

    result = {
        "triangles": int(len(scene.mesh.faces)),
        "nodes": host.bvh.n_nodes,
        "pack_s": pack_s,
        "tri_v_bytes": host.tri_v.nbytes,
        # nodes and, where the tree has them, leaf blocks (triangles tested by the traversal)
        "bvh_bytes": sum(
            getattr(host, k).nbytes for k in ("bvh_bounds", "bvh_children", "bvh_leaves") if hasattr(host, k)
        ),
    }
    for key, rays, times in (("camera", count, t1), ("bounce", len(o2), t2), ("bounce_sorted", len(o2), t2_sorted)):
        result[f"{key}_rays"] = rays
        result[f"{key}_rays_per_s"] = rays / median(times[:, 0])
        result[f"{key}_rays_per_cpu_s"] = rays / median(times[:, 1])
    try:  # visits per ray, from a build that counts them
        stats = build_program(context, "traversal.cl", ("-D BVH_STATS",))
        for key, o, d in (("camera", o1, d1), ("bounce", o2, d2)):
            visits = np.zeros((len(o), 2), np.int32)
            trace(stats, o, d, visits)
            result[f"{key}_nodes_per_ray"], result[f"{key}_tris_per_ray"] = visits.mean(0).tolist()
    except cl.Error:
        pass  # a tree whose bvh.h does not count

    # Whole B = 1 renders, closest hits only (2 rays per sample), interleaved with Mitsuba's
    # path tracer at max_depth 2 (3 rays per sample: camera, emitter sample's shadow ray, BSDF ray).
    bare = Features.only(max_bounces=1, emission=True, environment=True, window=True)
    runners = [("render_b1", InvrenderRunner(scene, camera, bare, device, host=host), 2)]
    if settings.mitsuba and choose_variant()[0] == "llvm_ad_rgb":
        runners.append(("mitsuba_b1", MitsubaRunner(scene, camera, 1, "llvm_ad_rgb"), 3))
    times = {name: [] for name, _, _ in runners}
    for name, runner, _ in runners:
        runner.warm_up()
    for rep in range(settings.repeats):
        for name, runner, _ in runners if rep % 2 == 0 else runners[::-1]:
            times[name].append(clock(runner.render, settings.spp)[1:])
    for name, _, rays in runners:
        t = np.array(times[name])
        result[f"{name}_rays_per_s"] = rays * count / median(t[:, 0])
        result[f"{name}_rays_per_cpu_s"] = rays * count / median(t[:, 1])
    if hits_path:
        tri = lambda h: np.where(h[:, 3].view(np.int32) < 0, -1, host.tri_id[np.maximum(h[:, 3].view(np.int32), 0)])
        np.savez(hits_path, camera_tri=tri(h1), camera_t=h1[:, 0], bounce_tri=tri(h2), bounce_t=h2[:, 0])
    return result


def direction_order(origin, direction, bits: int = 10) -> np.ndarray:
    """Rays grouped by direction octant, then along a Morton curve of their origins (bits per
    axis), so that neighbours in a launch traverse the same nodes."""
    octant = ((direction[:, :3] < 0) * np.array([1, 2, 4])).sum(1).astype(np.uint64)
    p = origin[:, :3].astype(np.float64)
    cell = ((p - p.min(0)) / np.maximum(np.ptp(p, 0), 1e-30) * (2**bits - 1)).astype(np.uint64)
    morton = np.zeros(len(p), np.uint64)
    for bit in range(bits):
        for axis in range(3):
            morton |= ((cell[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(3 * bit + axis)
    return np.argsort(octant << np.uint64(3 * bits) | morton, kind="stable")


def _probe_process(tree: Path, triangles: int, settings: Settings, device, hits_path) -> dict:
    command = [
        sys.executable,
        "-m",
        "invrender.bench.traversal",
        "probe",
        "--triangles",
        str(triangles),
        "--settings",
        json.dumps(asdict(settings)),
        "--hits",
        str(hits_path),
    ]
    if device:
        command += ["--device", device]
    env = dict(os.environ, PYTHONPATH=str(tree / "workflow"))
    proc = subprocess.run(command, capture_output=True, text=True, env=env, cwd=tree)
    lines = [line for line in proc.stdout.splitlines() if line.startswith(MARK)]
    if proc.returncode != 0 or not lines:
        raise RuntimeError(f"traversal probe in {tree} failed ({proc.returncode}):\n{proc.stderr[-4000:]}")
    return json.loads(lines[-1][len(MARK) :])


def _same_hits(a, b) -> dict:
    """Rays for which two trees found different triangles (a ray one tree has and the other has
    not counts too), and the largest relative difference in t where they found the same."""
    out, rel = {}, [0.0]
    for key in ("camera", "bounce"):
        ta, tb = a[f"{key}_tri"], b[f"{key}_tri"]
        n = min(len(ta), len(tb))
        same = ta[:n] == tb[:n]
        out[f"{key}_rays_differ"] = int((~same).sum()) + max(len(ta), len(tb)) - n
        hit = same & (ta[:n] >= 0)
        rel += list(np.abs(a[f"{key}_t"][:n][hit] - b[f"{key}_t"][:n][hit]) / a[f"{key}_t"][:n][hit])
    out["max_rel_dt"] = float(np.max(rel))
    return out


def compare(settings: Settings, device=None, baseline: Path | None = None) -> list[dict]:
    """Per size: each tree's medians over rounds (interleaved A B, B A, ...)."""
    trees = [("this", TREE)]
    if baseline:
        for name in ("kernels/traversal.cl", "workflow/invrender/bench/traversal.py"):
            shutil.copy(TREE / name, baseline / name)  # the same measurement in both trees
        trees.append(("baseline", baseline))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for size in settings.sizes:
            runs = {name: [] for name, _ in trees}
            for r in range(settings.rounds):
                for name, tree in trees if r % 2 == 0 else trees[::-1]:
                    # Mitsuba once, beside this tree
                    tree_settings = settings if name == "this" else replace(settings, mitsuba=False)
                    runs[name].append(_probe_process(tree, size, tree_settings, device, Path(tmp) / f"{name}.npz"))
            for name, _ in trees:
                row = dict(runs[name][0], tree=name, rounds=len(runs[name]))
                for key in (k for k in row if k.endswith("_s")):
                    row[key] = median([run[key] for run in runs[name]])
                rows.append(row)
            if baseline:
                # Ratios of the runs side by side in one round, median over the rounds.
                for key in (k for k in rows[-1] if k.endswith("per_s") or k.endswith("per_cpu_s")):
                    ratios = [a[key] / b[key] for a, b in zip(runs["this"], runs["baseline"])]
                    rows[-2]["x_" + key.replace("_rays_per", "")] = median(ratios)
                this, base = (np.load(Path(tmp) / f"{name}.npz") for name in ("this", "baseline"))
                rows[-2].update(_same_hits(this, base))
    return rows


COLUMNS = [
    ("tree", "tree", "s"),
    ("triangles", "triangles", "d"),
    ("bvh_bytes", "BVH bytes", "d"),
    ("tri_v_bytes", "tri_v bytes", "d"),
    ("camera_rays_per_s", "camera rays/s", ".3g"),
    ("bounce_rays_per_s", "bounce rays/s", ".3g"),
    ("bounce_sorted_rays_per_s", "bounce sorted rays/s", ".3g"),
    ("render_b1_rays_per_s", "B=1 render rays/s", ".3g"),
    ("mitsuba_b1_rays_per_s", "mitsuba B=1 rays/s", ".3g"),
    ("camera_rays_per_cpu_s", "camera rays/cpu-s", ".3g"),
    ("bounce_rays_per_cpu_s", "bounce rays/cpu-s", ".3g"),
    ("camera_nodes_per_ray", "nodes/ray cam", ".1f"),
    ("camera_tris_per_ray", "tris/ray cam", ".1f"),
    ("bounce_nodes_per_ray", "nodes/ray bounce", ".1f"),
    ("bounce_tris_per_ray", "tris/ray bounce", ".1f"),
    ("x_camera_s", "x cam", ".2f"),
    ("x_bounce_s", "x bounce", ".2f"),
    ("x_render_b1_s", "x render", ".2f"),
    ("x_camera_cpu_s", "x cam cpu", ".2f"),
    ("x_bounce_cpu_s", "x bounce cpu", ".2f"),
    ("x_render_b1_cpu_s", "x render cpu", ".2f"),
    ("camera_rays_differ", "rays differ cam", "d"),
    ("bounce_rays_differ", "rays differ bounce", "d"),
    ("max_rel_dt", "max rel dt", ".1e"),
]


def run(quick: bool = False, out="docs/benchmarks", device: str | None = None, baseline=None) -> dict:
    settings, out, variant, notes, started, load_start = start_run(
        "traversal", QUICK if quick else FULL, out, lambda s: s
    )
    results = {"traversal": compare(settings, device, Path(baseline).resolve() if baseline else None)}
    report = run_report("traversal", settings, variant, notes, started, load_start, device, results)
    title = (
        f"# invrender bench traversal ({settings.mode}; {settings.width}x{settings.height}, "
        f"{settings.spp} spp, room view {settings.view}; {report['seconds']:.0f} s)"
    )
    columns = [c for c in COLUMNS if any(c[0] in row for row in results["traversal"])]
    write_report(out, "traversal", title, report, {"traversal": ("Closest-hit traversal", columns)}, ("traversal",))
    return report


def _main(argv=None) -> int:
    parser = argparse.ArgumentParser(description="`invrender bench traversal` and its per-size probe")
    sub = parser.add_subparsers(dest="command", required=True)
    p = sub.add_parser("probe", help="one size, measured in this process; prints one JSON line")
    p.add_argument("--triangles", type=int, required=True)
    p.add_argument("--settings", required=True)
    p.add_argument("--hits")
    p.add_argument("--device")
    r = sub.add_parser("run", help="the benchmark, optionally A/B against another source tree")
    r.add_argument("--quick", action="store_true")
    r.add_argument("--out", default="docs/benchmarks")
    r.add_argument("--device")
    r.add_argument("--baseline", help="another source tree (workflow/, kernels/) to alternate with")
    args = parser.parse_args(argv)
    quiet_pyopencl()
    if args.command == "probe":
        settings = replace(FULL, **json.loads(args.settings))
        settings = replace(settings, sizes=tuple(settings.sizes))
        print(MARK + json.dumps(probe(args.triangles, settings, args.device, args.hits)), flush=True)
    else:
        run(args.quick, args.out, args.device, args.baseline)
    return 0


if __name__ == "__main__":
    sys.exit(_main())

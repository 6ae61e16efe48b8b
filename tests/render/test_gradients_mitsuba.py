"""The adjoint's d Loss / d kd against Mitsuba 3's gradient of the same loss on the same scene.

A closed, all-diffuse box room lit by emitting texels in its ceiling, every surface textured
from a 32 x 32 kd atlas (one 8 x 8 tile per surface), seen by a 64 x 48 camera; B = 3 bounces.
The loss is linear, sum over pixels and channels of w * L with fixed random weights w, so its
gradient is the adjoint-weighted dL/dkd and one backward pass per seed is an unbiased sample of
it (no forward/backward correlation to worry about).

Mitsuba's side, chosen by what is installed:
- `prb` (path replay backpropagation, `llvm_ad_rgb`): its gradient of the same loss w.r.t. the
  kd bitmap of a two-sided `diffuse` BSDF (invrender/mitsuba/, `scene_to_mitsuba_diffuse`),
  compared in 4 x 4 texel blocks per channel;
- central differences of renders in the default variant (`llvm_ad_rgb` or, without LLVM,
  `scalar_rgb`) with common random numbers (one seed for both sides of a difference; with no
  Russian roulette and kd-independent sampling the paths are the same), kd of one surface's tile
  moved at a time, compared per surface and channel. This runs in either variant, so a machine
  without LLVM checks the gradient too (tests/bench runs the scalar_rgb fallback where LLVM is
  usable).

Each side's mean over independent seeds has a standard error from the spread over the seeds;
the two must agree within Z_MAX combined standard errors beyond a relative SLACK. The same check
must reject our gradient scaled by 1.1 and our gradient with its atlas rows flipped (the v
convention got wrong), so a pass means the tolerance can tell.
"""

from __future__ import annotations

import drjit as dr
import mitsuba as mi
import numpy as np
import pytest
from testscenes import look_at_camera, quad

# The bridge first: on import it points drjit at a libLLVM that works (DRJIT_LIBLLVM_PATH).
import invrender.mitsuba as mb  # noqa: I001
from invrender.render.adjoint import backward
from invrender.render.features import Features
from invrender.render.renderer import Renderer, pixel_requests
from invrender.scene.types import Maps, Mesh, Scene

BOUNCES = 3
TILE, GRID = 8, 4  # atlas GRID x GRID tiles of TILE x TILE texels: 32 x 32
BLOCK = 4  # texel blocks compared against prb
SEEDS = 16  # independent runs per side: their spread is each side's standard error
SPP = 32  # per run, both sides
FD_SEEDS, FD_SPP, FD_STEP = 8, 32, 0.05
Z_MAX = 4.0  # combined standard errors allowed beyond the slack
# The two estimators should share no systematic term (same model, same pixel box filter, same
# nearest texels). Measured: at 48 seeds x 128 spp per side the surfaces agree within 0.25 %
# (chi^2 per 4x4 block 0.97); at this test's size, over four other seed sets, max |z| over the 84
# blocks was 3.1-4.3 without slack (16 seeds make the standard errors themselves noisy) and
# 1.5-2.1 with it, while the wrong gradients score 27-33 (scaled) and > 1,000 (flipped).
SLACK = 0.01
WRONG_SCALE = 1.1


def textured_box_room() -> tuple[Scene, list[np.ndarray]]:
    """The room and, per surface, the (row, column) texel slices of its tile."""
    W, H, D = 2.0, 2.6, 1.5
    surfaces = [
        quad((0, 0, 0), (0, 0, D), (W, 0, 0)),  # floor, front +Y
        quad((0, H, 0), (W, 0, 0), (0, 0, D)),  # ceiling, front -Y: its emitting texels face into the room
        quad((0, H / 2, -D), (W, 0, 0), (0, H / 2, 0)),  # back wall, front +Z
        quad((0, H / 2, D), (0, H / 2, 0), (W, 0, 0)),  # front wall, front -Z
        quad((-W, H / 2, 0), (0, H / 2, 0), (0, 0, D)),  # left wall, front +X
        quad((W, H / 2, 0), (0, 0, D), (0, H / 2, 0)),  # right wall, front -X
        quad((-0.8, 0.4, -0.3), (0.3, 0, 0), (0, 0, 0.3)),  # a table top, front down: seen from its back
    ]
    inset = 1e-3  # keeps a tile's border texels off its neighbours' under nearest lookup
    uvs, tiles = [], []
    for index, (_, _, uv) in enumerate(surfaces):
        row, col = divmod(index, GRID)  # tile row counted from the top of the atlas
        u = (col + inset + (1 - 2 * inset) * uv[:, 0]) / GRID
        v = 1 - (row + 1 - inset - (1 - 2 * inset) * uv[:, 1]) / GRID  # v up: atlas row = floor((1 - v) N)
        uvs.append(np.stack([u, v], -1))
        tiles.append((slice(row * TILE, (row + 1) * TILE), slice(col * TILE, (col + 1) * TILE)))
    mesh = Mesh(
        np.concatenate([p for p, _, _ in surfaces]).astype(np.float32),
        np.concatenate([f + 4 * i for i, (_, f, _) in enumerate(surfaces)]).astype(np.int32),
        np.concatenate(uvs).astype(np.float32),
        np.repeat(np.arange(len(surfaces)) + 1, 2).astype(np.int32),
    )
    n = TILE * GRID
    maps = Maps.uniform(size=(n, n), kd=0.5, ks=0.0, ka=0.1, kg=0.0, cube=4)
    maps.kd[:] = np.random.default_rng(1).uniform(0.3, 0.8, (n, n, 3))
    rows, cols = tiles[1]
    maps.ke[rows.start + 2 : rows.start + 6, cols.start + 2 : cols.start + 6] = 6.0  # a 4 x 4-texel ceiling light
    camera = look_at_camera((-1.2, 1.4, 1.2), (0.5, 0.8, -0.8), width=64, height=48, fov_x_deg=75)
    return Scene(mesh, maps, [camera]), tiles


@pytest.fixture(scope="module")
def room():
    scene, tiles = textured_box_room()
    camera = scene.cameras[0]
    weights = np.random.default_rng(2).uniform(0.5, 1.5, (camera.height, camera.width, 3)).astype(np.float32)
    features = Features.only(max_bounces=BOUNCES, emission=True, emitter_sampling=True)
    return scene, tiles, camera, weights, Renderer(scene, features)


@pytest.fixture(scope="module")
def ours(room):
    """d Loss / d kd from the adjoint, one (N, N, 3) map per seed."""
    scene, _, camera, weights, renderer = room
    requests = pixel_requests(camera)
    return np.stack(
        [backward(renderer, [camera], requests, weights.reshape(-1, 3), SPP, seed=seed)["kd"] for seed in range(SEEDS)]
    )


def mitsuba_prb(scene, camera, weights) -> np.ndarray:
    """Mitsuba's d Loss / d kd, one (N, N, 3) map per seed: mi.render with the kd bitmap
    tracking gradients, dr.backward of the loss."""
    loaded = mi.load_dict(
        mb.scene_to_mitsuba_diffuse(scene, camera, BOUNCES, SPP, "llvm_ad_rgb", integrator=mb.prb_integrator(BOUNCES)),
        parallel=False,
    )
    params = mi.traverse(loaded)
    key = mb.kd_parameter(params)
    dr.enable_grad(params[key])
    params.update()
    w = mi.TensorXf(weights)
    grads = []
    for seed in range(SEEDS):
        image = mi.render(loaded, params, spp=SPP, seed=1000 + seed)
        dr.backward(dr.sum(w * image, axis=None))
        grads.append(np.array(dr.grad(params[key]), np.float64))
        dr.set_grad(params[key], 0.0)
    return np.stack(grads)


def mitsuba_central_differences(scene, camera, weights, tiles) -> np.ndarray:
    """(seeds, surfaces, 3): d Loss / d(kd of every texel of a surface's tile, per channel) by
    central differences of renders with common random numbers. Channels do not mix in
    RGB, so one pair of renders per surface gives all three."""
    loaded = mi.load_dict(
        mb.scene_to_mitsuba_diffuse(
            scene, camera, BOUNCES, FD_SPP, mb.DEFAULT_VARIANT, integrator=mb.path_integrator(BOUNCES)
        ),
        parallel=False,
    )
    params = mi.traverse(loaded)
    key = mb.kd_parameter(params)
    kd = np.array(params[key], np.float32)
    w = weights.astype(np.float64)
    out = np.zeros((FD_SEEDS, len(tiles), 3))
    for s in range(FD_SEEDS):
        for t, tile in enumerate(tiles):
            losses = []
            for sign in (1, -1):
                moved = kd.copy()
                moved[tile] += sign * FD_STEP
                params[key] = mi.TensorXf(moved)
                params.update()
                image = np.array(mi.render(loaded, spp=FD_SPP, seed=2000 + s), np.float64)[..., :3]
                losses.append((w * image).sum((0, 1)))
            out[s, t] = (losses[0] - losses[1]) / (2 * FD_STEP)
    params[key] = mi.TensorXf(kd)
    params.update()
    return out


def block_sums(grad: np.ndarray) -> np.ndarray:
    """(..., N, N, 3) -> (..., N / BLOCK, N / BLOCK, 3): sums over BLOCK x BLOCK texels."""
    n = grad.shape[-2]
    return grad.reshape(*grad.shape[:-3], n // BLOCK, BLOCK, n // BLOCK, BLOCK, 3).sum((-4, -2))


def tile_sums(grad: np.ndarray, tiles) -> np.ndarray:
    """(..., N, N, 3) -> (..., surfaces, 3)."""
    return np.stack([grad[..., rows, cols, :].sum((-3, -2)) for rows, cols in tiles], -2)


def excess_z(ours: np.ndarray, theirs: np.ndarray) -> np.ndarray:
    """|mean difference| beyond SLACK x |Mitsuba's mean|, in combined standard errors of the two
    means (from the spread over each side's seeds), for every compared value."""
    a, b = ours.reshape(len(ours), -1), theirs.reshape(len(theirs), -1)
    se = np.sqrt(a.var(0, ddof=1) / len(a) + b.var(0, ddof=1) / len(b))
    excess = np.maximum(np.abs(a.mean(0) - b.mean(0)) - SLACK * np.abs(b.mean(0)), 0.0)
    return excess / np.maximum(se, 1e-12)


def check(ours: np.ndarray, theirs: np.ndarray, what: str):
    """Agreement of the two samples, and that the wrong gradients are told apart."""
    used = np.abs(theirs.mean(0)).ravel() > 0
    assert used.sum() >= 20, f"{what}: only {used.sum()} compared values"
    z = excess_z(ours, theirs)[used]
    a, b = ours.mean(0).ravel()[used], theirs.mean(0).ravel()[used]
    se = np.sqrt(ours.reshape(len(ours), -1).var(0, ddof=1)[used] / len(ours))
    print(
        f"{what}: {used.sum()} values, max excess |z| {z.max():.2f}, median relative standard error of ours "
        f"{np.median(se / np.abs(b)):.2%}, sum ours / Mitsuba {a.sum() / b.sum():.4f}"
    )
    assert z.max() < Z_MAX, f"{what}: max excess |z| {z.max():.2f} >= {Z_MAX} (ours {a}, Mitsuba {b})"
    return z


def wrong_versions(grad: np.ndarray) -> dict[str, np.ndarray]:
    return {f"scaled by {WRONG_SCALE}": WRONG_SCALE * grad, "atlas rows flipped": grad[..., ::-1, :, :]}


# prb where Mitsuba's LLVM backend works (the bridge's default variant); the central differences in
# either variant (without LLVM, the only check).
METHODS = (["prb"] if mb.DEFAULT_VARIANT == "llvm_ad_rgb" else []) + ["central differences"]


@pytest.mark.parametrize("method", METHODS)
def test_kd_gradient_matches_mitsuba(room, ours, method):
    scene, tiles, camera, weights, _ = room
    if method == "prb":
        theirs, aggregate, what = block_sums(mitsuba_prb(scene, camera, weights)), block_sums, "prb, 4x4 blocks"
    else:
        theirs = mitsuba_central_differences(scene, camera, weights, tiles)
        aggregate, what = (
            (lambda grad: tile_sums(grad, tiles)),
            f"{mb.DEFAULT_VARIANT} central differences, per surface",
        )
    check(aggregate(ours), theirs, what)
    for name, wrong in wrong_versions(ours).items():
        z = excess_z(aggregate(wrong), theirs)
        assert z.max() > Z_MAX, f"{what}: the tolerance does not reject our gradient {name} (max |z| {z.max():.2f})"

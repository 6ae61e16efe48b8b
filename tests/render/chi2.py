"""Chi-square goodness-of-fit test for direction samplers on the unit sphere.

In the style of Mitsuba 3's `mitsuba.chi2.ChiSquareTest` (src/python/python/chi2.py) and
pbrt-v3's src/tests/bsdfs.cpp: bin the sphere in (cos theta, phi) (equal-area cells), integrate
the PDF over each cell numerically (adaptive composite Simpson, so cube-map texel edges,
triangle edges and sharp lobes are resolved), pool cells with small expected counts, compute
Pearson's statistic and its p-value, and reject at a Sidak-corrected significance level.

Generic: a sampler is `sample_fn(n) -> (n, 3)` directions with failed samples as NaN rows, a
density is `pdf_fn(dirs (m, 3)) -> (m,)` over solid angle. A sampler that can fail has a PDF
that integrates to its success probability; the failures are a cell of their own (observed
vs n (1 - integral)), so a wrong normalisation is caught too. A sample where the PDF is 0
rejects outright.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import stats


def sidak_threshold(significance: float, test_count: int) -> float:
    """Per-test level so that test_count independent tests reject a correct sampler with
    probability `significance` in all: 1 - (1 - significance)^(1 / test_count) (Sidak 1967)."""
    return 1.0 - (1.0 - significance) ** (1.0 / test_count)


def _simpson(k: int):
    """Nodes in [0, 1] and weights of composite Simpson's rule with k (even) intervals."""
    x = np.linspace(0.0, 1.0, k + 1)
    w = np.ones(k + 1)
    w[1:-1:2], w[2:-1:2] = 4.0, 2.0
    return x, w / (3.0 * k)


def _rule(pdf_fn, z0, dz, p0, dp, k: int, chunk: int):
    """Composite Simpson on (k + 1) x (k + 1) nodes, edges included, of each rectangle
    [z0, z0 + dz] x [p0, p0 + dp] in (z = cos theta, phi), whose area element is dz dphi:
    (m,) integrals. Nodes on the edges see a discontinuity that crosses the rectangle unless
    it cuts off a sliver between two edge nodes (area O(h^3))."""
    f, w = _simpson(k)
    z = z0[:, None, None] + dz[:, None, None] * f[None, :, None]
    phi = p0[:, None, None] + dp[:, None, None] * f[None, None, :]
    z, phi = np.broadcast_arrays(z, phi)
    r = np.sqrt(np.maximum(0.0, 1.0 - z * z))
    dirs = np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=-1).reshape(-1, 3)
    values = np.concatenate(
        [np.asarray(pdf_fn(dirs[a : a + chunk]), dtype=np.float64).reshape(-1) for a in range(0, len(dirs), chunk)]
        or [np.zeros(0)]
    )
    if not np.all(np.isfinite(values)) or np.any(values < 0):
        raise ValueError("pdf_fn returned a negative or non-finite density")
    values = values.reshape(len(z0), k + 1, k + 1)
    return np.einsum("mij,i,j->m", values, w, w) * dz * dp


def integrate_cells(
    pdf_fn, res=(20, 40), tol: float = 1e-7, k: int = 4, min_depth: int = 0, max_depth: int = 6, chunk: int = 1 << 18
) -> np.ndarray:
    """(res_z, res_phi) probability of each cell: the integral of pdf_fn over it.

    Adaptive: a rectangle's Simpson estimate (`_rule`) is compared with the sum of its four
    quadrants' estimates; where they differ by more than tol (absolute probability), the
    quadrants are refined in turn, at least min_depth and at most max_depth halvings. PDFs
    with discontinuities (cube map texels, triangle edges, the horizon) and sharp peaks get
    their cells right without a dense grid everywhere."""
    res_z, res_phi = res
    iz, ip = np.divmod(np.arange(res_z * res_phi), res_phi)
    dz0, dp0 = 2.0 / res_z, 2.0 * np.pi / res_phi
    z0, p0 = -1.0 + iz * dz0, ip * dp0
    dz, dp = np.full(len(iz), dz0), np.full(len(iz), dp0)
    coarse = _rule(pdf_fn, z0, dz, p0, dp, k, chunk)
    out = np.zeros(res_z * res_phi)
    cell = np.arange(res_z * res_phi)
    for depth in range(max_depth + 1):
        # the four quadrants of every active rectangle, quadrant-major
        hz, hp = dz / 2, dp / 2
        cz0 = np.concatenate([z0, z0 + hz, z0, z0 + hz])
        cp0 = np.concatenate([p0, p0, p0 + hp, p0 + hp])
        chz, chp = np.tile(hz, 4), np.tile(hp, 4)
        child = _rule(pdf_fn, cz0, chz, cp0, chp, k, chunk)
        fine = child.reshape(4, -1).sum(axis=0)
        done = ((np.abs(fine - coarse) <= tol) & (depth >= min_depth)) | (depth == max_depth)
        np.add.at(out, cell[done], fine[done])
        keep = np.tile(~done, 4)
        z0, p0, dz, dp = cz0[keep], cp0[keep], chz[keep], chp[keep]
        coarse, cell = child[keep], np.tile(cell, 4)[keep]
        if len(z0) == 0:
            break
    return out.reshape(res_z, res_phi)


def pdf_integral(pdf_fn, res=(20, 40), tol: float = 1e-8) -> float:
    """Integral of pdf_fn over the sphere: 1, or the success probability of a failing sampler."""
    return float(integrate_cells(pdf_fn, res, tol).sum())


def histogram(dirs, res=(20, 40)):
    """(counts (res_z, res_phi), number of failed samples) of (n, 3) directions (NaN = failed)."""
    dirs = np.asarray(dirs, dtype=np.float64)
    norm = np.linalg.norm(dirs, axis=-1)
    ok = np.all(np.isfinite(dirs), axis=-1) & (norm > 0)
    d = dirs[ok] / norm[ok, None]
    res_z, res_phi = res
    z = np.clip(d[:, 2], -1.0, 1.0)
    phi = np.mod(np.arctan2(d[:, 1], d[:, 0]), 2.0 * np.pi)
    iz = np.clip(((z + 1.0) * 0.5 * res_z).astype(np.int64), 0, res_z - 1)
    ip = np.clip((phi / (2.0 * np.pi) * res_phi).astype(np.int64), 0, res_phi - 1)
    counts = np.bincount(iz * res_phi + ip, minlength=res_z * res_phi).reshape(res_z, res_phi)
    return counts, int((~ok).sum())


@dataclass
class Chi2Result:
    passed: bool
    p_value: float
    threshold: float
    statistic: float
    dof: int
    message: str
    valid_fraction: float
    integral: float
    observed: np.ndarray = field(repr=False)
    expected: np.ndarray = field(repr=False)

    def __bool__(self):
        return self.passed


def pearson(observed, expected, min_expected: float = 5.0):
    """(statistic, dof, message) of Pearson's chi-square over cells; cells with expected count
    below min_expected (including 0: a sliver of support the cell quadrature missed) are pooled
    into one cell, which is merged into the smallest regular cell if the pool stays below
    min_expected. Samples where the PDF is really 0 are caught per sample by `chi2_test`."""
    o = np.asarray(observed, dtype=np.float64).ravel()
    e = np.asarray(expected, dtype=np.float64).ravel()
    small = e < min_expected
    cells_o, cells_e = list(o[~small]), list(e[~small])
    pool_o, pool_e = o[small].sum(), e[small].sum()
    if pool_e >= min_expected:
        cells_o.append(pool_o)
        cells_e.append(pool_e)
    elif pool_e > 0 or pool_o > 0:
        if not cells_e:
            return np.inf, 1, "all cells have expected count below the minimum"
        j = int(np.argmin(cells_e))
        cells_o[j] += pool_o
        cells_e[j] += pool_e
    cells_o, cells_e = np.array(cells_o), np.array(cells_e)
    if len(cells_e) < 2:
        return 0.0, 0, "fewer than two cells: nothing to test"
    stat = float(np.sum((cells_o - cells_e) ** 2 / cells_e))
    return stat, len(cells_e) - 1, f"{len(cells_e)} cells ({int(small.sum())} pooled)"


def chi2_test(
    sample_fn,
    pdf_fn,
    n_samples: int = 1_000_000,
    res=(20, 40),
    tol: float | None = None,
    significance: float = 0.01,
    test_count: int = 1,
    min_expected: float = 5.0,
    sub: int | None = None,
):
    """Run the test: n_samples from sample_fn, expected counts n * (integral of pdf_fn over
    each cell, `integrate_cells` with absolute tolerance tol, default 0.5 / n: half a sample),
    plus a cell for failed samples with expected count n (1 - integral of pdf_fn) (left out
    when nothing failed and the PDF integrates to 1 within 1e-3). A valid
    sample where pdf_fn is 0 rejects outright (the sampler leaves the PDF's support).
    sub: optional minimum number of integration intervals per cell side before the adaptive
    refinement decides (rounded up to 8 * 2^d); the adaptive rule alone usually suffices.
    Returns a Chi2Result (truthy when the sampler is accepted at the Sidak-corrected level)."""
    dirs = np.asarray(sample_fn(n_samples), dtype=np.float64)
    if dirs.shape != (n_samples, 3):
        raise ValueError(f"sample_fn returned shape {dirs.shape}, expected ({n_samples}, 3)")
    counts, failed = histogram(dirs, res)
    valid = dirs[np.all(np.isfinite(dirs), axis=-1) & (np.linalg.norm(dirs, axis=-1) > 0)]
    outside = int(np.sum(np.asarray(pdf_fn(normalize_rows(valid))) <= 0))
    min_depth = 0 if sub is None else max(0, math.ceil(math.log2(sub / 8)))
    prob = integrate_cells(pdf_fn, res, 0.5 / n_samples if tol is None else tol, min_depth=min_depth)
    integral = float(prob.sum())
    expected = prob * n_samples
    e_fail = max(0.0, 1.0 - integral) * n_samples
    observed_all, expected_all = counts.ravel(), expected.ravel()
    # The failure cell, unless the sampler never fails and the PDF says so up to the cell
    # quadrature's error (~1e-5 of the mass; 20 expected failures against 0 would dominate).
    if failed > 0 or e_fail > max(min_expected, 1e-3 * n_samples):
        observed_all = np.append(observed_all, failed)
        expected_all = np.append(expected_all, e_fail)
    stat, dof, message = pearson(observed_all, expected_all, min_expected)
    if outside:
        stat, message = np.inf, f"{outside} samples where the PDF is 0; " + message
    p = float(stats.chi2.sf(stat, dof)) if dof > 0 and np.isfinite(stat) else (1.0 if dof == 0 else 0.0)
    threshold = sidak_threshold(significance, test_count)
    passed = p >= threshold
    message = (
        f"{'accepted' if passed else 'REJECTED'}: p = {p:.3g} vs {threshold:.3g}, "
        f"chi2 = {stat:.1f}, dof = {dof}, {message}, valid {1 - failed / n_samples:.4f}, "
        f"pdf integral {integral:.4f}"
    )
    return Chi2Result(passed, p, threshold, stat, dof, message, 1.0 - failed / n_samples, integral, counts, expected)


def normalize_rows(d):
    return d / np.linalg.norm(d, axis=-1, keepdims=True)

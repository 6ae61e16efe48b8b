"""The float64 reference of the light-sampling strategies.

docs/renderer.md ("Textures", "Sampling") is the contract. Strategies 1 and 2 (cosine and
Beckmann) live in `bsdf.py`; this file has strategy 3 (environment cube map by luminance),
strategy 4 (emitting triangles by power, "all hits" PDF) and the one-sample mixture.

The cube map convention (face order, texel <-> direction, texel solid angles) is
scene/cubemap.py's; this file samples by it.
"""

from __future__ import annotations

import numpy as np

from invrender.render import bsdf
from invrender.render.bsdf import luminance
from invrender.scene.cubemap import as_cube, cube_texel, cube_texel_solid_angles, cube_to_direction, direction_to_cube

STRATEGIES = ("diffuse", "specular", "environment", "emitter")


def _f64(*arrays):
    return [np.asarray(a, dtype=np.float64) for a in arrays]


def _pick(cdf, u):
    """Inverse CDF: the first index i with cdf[i] > u (never a zero-probability entry, since
    those repeat the previous cdf value). cdf is nondecreasing with cdf[-1] == 1 exactly."""
    u = np.asarray(u, dtype=np.float64)
    return np.minimum(np.searchsorted(cdf, u, side="right"), len(cdf) - 1)


def _cdf(weights):
    """(probabilities, cdf) of nonnegative weights; cdf[-1] = 1 exactly (divided by its own
    last entry), probabilities = weights / the same total."""
    cum = np.cumsum(weights)
    return weights / cum[-1], cum / cum[-1]


# --------------------------------------------------------------------------------------------
# strategy 3: environment cube map by luminance x solid angle


class EnvironmentDistribution:
    """Texel probability P proportional to luminance(kg) x texel solid angle (docs strategy 3).

    Texels are flattened in storage order (face, row, column). Negative luminance counts as 0.
    If the whole map is black, P falls back to the texel solid angle (uniform directions), so
    the density stays valid; the renderer should then give the strategy weight 0.
    """

    def __init__(self, kg):
        kg = as_cube(kg).astype(np.float64)
        self.n = n = kg.shape[1]
        self.solid_angle = np.broadcast_to(cube_texel_solid_angles(n), (6, n, n))
        lum = np.maximum(luminance(kg[..., :3]), 0.0)
        weights = (lum * self.solid_angle).ravel()
        self.black = not weights.sum() > 0
        if self.black:
            weights = self.solid_angle.ravel().copy()
        self.prob, self.cdf = _cdf(weights)

    @property
    def texel_probability(self):
        """(6, N, N) P(texel)."""
        return self.prob.reshape(6, self.n, self.n)

    def sample(self, u1, u2, u3):
        """Texel by inverse CDF with u1, then a uniform point in the texel's face coordinates:
        s = (column + u2) / N, t = (row + u3) / N. Returns unit directions (..., 3)."""
        u2, u3 = _f64(u2, u3)
        idx = _pick(self.cdf, u1)
        face, rest = np.divmod(idx, self.n * self.n)
        row, col = np.divmod(rest, self.n)
        return cube_to_direction(face, (col + u2) / self.n, (row + u3) / self.n)

    def pdf(self, d):
        """Solid-angle density: P(texel) / (2/N)^2 * (1 + u^2 + v^2)^(3/2), (u, v) = face
        coordinates in [-1, 1] (uniform in (u, v) over a texel of area (2/N)^2, and
        d(omega) = du dv / (1 + u^2 + v^2)^(3/2) on the face plane at unit distance)."""
        face, s, t = direction_to_cube(d)
        row, col = cube_texel(s, t, self.n)
        p = self.prob[(face * self.n + row) * self.n + col]
        u, v = 2.0 * s - 1.0, 2.0 * t - 1.0
        return p / (2.0 / self.n) ** 2 * (1.0 + u * u + v * v) ** 1.5


# --------------------------------------------------------------------------------------------
# strategy 4: emitting triangles by power, PDF over every hit ("all hits")


class EmitterDistribution:
    """Triangle t with probability P(t) proportional to power[t] (= area x mean luminance of ke,
    supplied by the caller), then a uniform point on it (docs strategy 4).

    v0, v1, v2: (T, 3) vertices; power: (T,). Degenerate (zero-area) triangles get P = 0.
    one_sided: (T,) bool or None: triangles that emit only on their front (counter-clockwise)
    side; a point sampled on one that x sees from behind is a spent sample, and `pdf` leaves
    such crossings out.
    """

    def __init__(self, v0, v1, v2, power, one_sided=None):
        self.v0, self.v1, self.v2 = _f64(v0, v1, v2)
        self.one_sided = np.zeros(len(self.v0), bool) if one_sided is None else np.asarray(one_sided, bool)
        power = np.maximum(np.asarray(power, dtype=np.float64), 0.0)
        cross = np.cross(self.v1 - self.v0, self.v2 - self.v0)
        twice_area = np.linalg.norm(cross, axis=-1)
        self.area = 0.5 * twice_area
        self.normal = cross / np.where(twice_area > 0, twice_area, 1.0)[:, None]
        power = np.where(self.area > 0, power, 0.0)
        if not power.sum() > 0:
            raise ValueError("EmitterDistribution: no triangle has positive power and area")
        self.prob, self.cdf = _cdf(power)

    def sample_point(self, u1, u2, u3):
        """(triangle index, point y): triangle by inverse CDF with u1, then the square-root
        parametrisation (pbrt-v3 13.6.5 UniformSampleTriangle; Osada et al. 2002):
        b0 = 1 - sqrt(u2), b1 = u3 sqrt(u2), b2 = 1 - b0 - b1, y = b0 v0 + b1 v1 + b2 v2."""
        u2, u3 = _f64(u2, u3)
        tri = _pick(self.cdf, u1)
        r = np.sqrt(u2)
        b0 = 1.0 - r
        b1 = u3 * r
        b2 = 1.0 - b0 - b1
        y = b0[..., None] * self.v0[tri] + b1[..., None] * self.v1[tri] + b2[..., None] * self.v2[tri]
        return tri, y

    def sample(self, x, u1, u2, u3):
        """Unit direction from x to a sampled emitter point; the zero vector if y == x (the
        sample fails: its PDF is 0)."""
        (x,) = _f64(x)
        tri, y = self.sample_point(u1, u2, u3)
        behind = self.one_sided[tri] & ~(np.sum(self.normal[tri] * (y - x), axis=-1) < 0)
        return np.where(behind[..., None], 0.0, bsdf.normalize(y - x))

    def pdf(self, x, d, t_min: float = 0.0, chunk: int = 1 << 15):
        """Solid-angle density of `sample` at direction d from x: the sum over EVERY emitting
        triangle the ray x + s d (s > t_min) crosses of P(t) / area(t) * s^2 / |n_t . d|
        (area-to-solid-angle Jacobian dist^2 / cos, pbrt-v3 Eq. 5.6; d is normalised first so
        s is the distance). Brute force over triangles with Moller-Trumbore (JGT 1997); a ray
        parallel to a triangle's plane (det = 0) does not cross it. x, d broadcast (..., 3)."""
        x, d = _f64(x, d)
        x, d = np.broadcast_arrays(x, d)
        shape = x.shape[:-1]
        x, d = x.reshape(-1, 3), bsdf.normalize(d.reshape(-1, 3))
        out = np.concatenate(
            [self._pdf_block(x[a : a + chunk], d[a : a + chunk], t_min) for a in range(0, len(x), chunk)]
            or [np.zeros(0)]
        )
        return out.reshape(shape)

    def _pdf_block(self, x, d, t_min):
        with np.errstate(over="ignore", invalid="ignore"):  # in rays that miss (masked)
            return self._pdf_block_unguarded(x, d, t_min)

    def _pdf_block_unguarded(self, x, d, t_min):
        out = np.zeros(len(x))
        dx, dy, dz = np.ascontiguousarray(d.T)  # component arrays: much faster than (n, 3)
        ox, oy, oz = np.ascontiguousarray(x.T)
        for t in np.flatnonzero(self.prob > 0):  # Moller-Trumbore, one triangle at a time
            (ax, ay, az), (bx, by, bz) = self.v1[t] - self.v0[t], self.v2[t] - self.v0[t]
            px, py, pz = dy * bz - dz * by, dz * bx - dx * bz, dx * by - dy * bx  # p = d x e2
            det = px * ax + py * ay + pz * az  # e1 . p
            inv = 1.0 / np.where(det != 0, det, 1.0)
            tx, ty, tz = ox - self.v0[t, 0], oy - self.v0[t, 1], oz - self.v0[t, 2]
            bu = (tx * px + ty * py + tz * pz) * inv
            qx, qy, qz = ty * az - tz * ay, tz * ax - tx * az, tx * ay - ty * ax  # q = tvec x e1
            bv = (dx * qx + dy * qy + dz * qz) * inv
            s = (qx * bx + qy * by + qz * bz) * inv  # distance along the unit d
            hit = (det != 0) & (bu >= 0) & (bv >= 0) & (bu + bv <= 1) & (s > t_min)
            if self.one_sided[t]:
                hit &= det > 0  # d . n < 0: the front
            nx, ny, nz = self.normal[t]
            cos = np.abs(dx * nx + dy * ny + dz * nz)
            out += np.where(hit, self.prob[t] / self.area[t] * s * s / np.where(hit, cos, 1.0), 0.0)
        return out


# --------------------------------------------------------------------------------------------
# the one-sample mixture (docs "Sampling: MILO's four-strategy mixture")


def mixture_weights(kd, ks, w_env: float = 0.25, w_emit: float = 0.25):
    """Strategy probabilities (..., 4) in the order of STRATEGIES:
    diffuse  = (1 - w_env - w_emit) L(kd) / (L(kd) + L(ks)),
    specular = (1 - w_env - w_emit) L(ks) / (L(kd) + L(ks)),   L = Rec. 709 luminance,
    (F(ks) at normal incidence is ks: wi.h = 1 in Schlick's formula), then w_env, w_emit.
    Negative channels count as 0. A black material (L(kd) + L(ks) = 0) gives the whole BSDF
    share to the diffuse strategy (its value does not matter there: f = 0)."""
    kd, ks = _f64(kd, ks)
    share = 1.0 - w_env - w_emit
    if w_env < 0 or w_emit < 0 or share < 0:
        raise ValueError(f"mixture_weights: need w_env, w_emit >= 0 and w_env + w_emit <= 1, got {w_env}, {w_emit}")
    ld = luminance(np.maximum(kd, 0.0))
    ls = luminance(np.maximum(ks, 0.0))
    tot = ld + ls
    pos = tot > 0
    tot_s = np.where(pos, tot, 1.0)
    w_d = np.where(pos, share * ld / tot_s, share)
    w_s = np.where(pos, share * ls / tot_s, 0.0)
    w_d, w_s = np.broadcast_arrays(w_d, w_s)
    return np.stack([w_d, w_s, np.full(w_d.shape, float(w_env)), np.full(w_d.shape, float(w_emit))], axis=-1)


def strategy_pdfs(n, wo, wi, ka, env=None, emitters=None, x=None, t_min: float = 0.0):
    """(..., 4) solid-angle densities of the four strategies at wi (0 for a missing one)."""
    n, wo, wi = _f64(n, wo, wi)
    shape = np.broadcast_shapes(n.shape, wo.shape, wi.shape, np.shape(ka) + (3,))[:-1]
    p_d = np.broadcast_to(bsdf.pdf_cosine(n, wi), shape)
    p_s = np.broadcast_to(bsdf.pdf_specular(n, wo, wi, ka), shape)
    p_g = np.broadcast_to(env.pdf(wi), shape) if env is not None else np.zeros(shape)
    if emitters is not None:
        if x is None:
            raise ValueError("strategy_pdfs: the emitter PDF needs the vertex position x")
        p_e = np.broadcast_to(emitters.pdf(x, wi, t_min=t_min), shape)
    else:
        p_e = np.zeros(shape)
    return np.stack([p_d, p_s, p_g, p_e], axis=-1)


def mixture_pdf(weights, n, wo, wi, ka, env=None, emitters=None, x=None, t_min: float = 0.0):
    """p_mix(wi) = sum_k w_k p_k(wi), over all four strategies whichever drew wi (one-sample
    MIS with the balance heuristic: Veach 1997, section 9.2.4). weights from `mixture_weights`;
    a strategy with weight > 0 needs its distribution (env, emitters and x)."""
    weights = np.asarray(weights, dtype=np.float64)
    if env is None and np.any(weights[..., 2] > 0):
        raise ValueError("mixture_pdf: w_env > 0 but no EnvironmentDistribution")
    if emitters is None and np.any(weights[..., 3] > 0):
        raise ValueError("mixture_pdf: w_emit > 0 but no EmitterDistribution")
    return np.sum(weights * strategy_pdfs(n, wo, wi, ka, env, emitters, x, t_min), axis=-1)


def choose_strategy(weights, u0):
    """Strategy index (...) from u0: the number of partial sums w0, w0+w1, w0+w1+w2 that are
    <= u0 (so a zero-weight strategy is never chosen), then, against rounding of the partial
    sums, stepped down past trailing zero weights."""
    weights = np.asarray(weights, dtype=np.float64)
    u0 = np.asarray(u0, dtype=np.float64)
    c = np.cumsum(weights, axis=-1)
    k = np.sum(u0[..., None] >= c[..., :3], axis=-1)
    weights = np.broadcast_to(weights, k.shape + (4,))
    for _ in range(3):
        wk = np.take_along_axis(weights, k[..., None], axis=-1)[..., 0]
        k = np.where((wk <= 0) & (k > 0), k - 1, k)
    return k


def sample_mixture(weights, n, wo, ka, u, env=None, emitters=None, x=None):
    """One direction from the mixture with the four uniforms u (..., 4) of one Philox call:
    u[0] chooses the strategy (`choose_strategy`), u[1], u[2] (and u[3]) drive it:
      diffuse:     bsdf.sample_cosine(n, u1, u2)
      specular:    bsdf.sample_specular(n, wo, ka, u1, u2)
      environment: env.sample(u1, u2, u3)
      emitter:     emitters.sample(x, u1, u2, u3)
    Returns (wi (..., 3), strategy (...))."""
    weights, n, wo, u = _f64(weights, n, wo, u)
    k = choose_strategy(weights, u[..., 0])
    u1, u2, u3 = u[..., 1], u[..., 2], u[..., 3]
    shape = k.shape + (3,)
    cands = [
        np.broadcast_to(bsdf.sample_cosine(n, u1, u2), shape),
        np.broadcast_to(bsdf.sample_specular(n, wo, ka, u1, u2), shape),
        np.broadcast_to(env.sample(u1, u2, u3), shape) if env is not None else np.zeros(shape),
        np.broadcast_to(emitters.sample(x, u1, u2, u3), shape) if emitters is not None else np.zeros(shape),
    ]
    wi = np.select([(k == j)[..., None] for j in range(4)], cands)
    return wi, k

"""The float64 reference of the renderer's material model and its two BSDF sampling strategies.

docs/renderer.md ("Material model", "Sampling") is the contract; the OpenCL kernels are tested
against these functions value for value, so every formula names its source.

Conventions (all functions vectorised over leading dimensions, broadcasting like numpy):

- n, wo, wi are unit vectors (..., 3); n is the geometric normal already flipped towards the
  incoming ray, wo = -d points to the viewer, wi to the light.
- kd, ks are RGB (..., 3); ka (...) is Beckmann alpha^2, clamped below at KA_MIN = 1e-6 (the
  lowest roughness the model supports; ka = 0 would make D a delta and 0/0 at h = n).
- Local frame: (b1, b2, n) from `branchless_onb`; a local vector (x, y, z) is
  x b1 + y b2 + z n.
"""

from __future__ import annotations

import functools
import math

import numpy as np

KA_MIN = 1e-6
# Rec. 709 / sRGB luminance weights (ITU-R BT.709-6, item 3.3), used for every "luminance".
REC709 = np.array([0.2126, 0.7152, 0.0722])
# F90 = min(1, F90_SLOPE * ks): Karis 2013, "Real Shading in Unreal Engine 4", p. 3 footnote
# ("anything less than 2% is physically impossible and is instead considered to be
# shadowing"): reflectance 0.02 and above reaches F90 = 1.
F90_SLOPE = 50.0
# Largest float64 below 1: keeps -log(1 - u) finite if a caller passes u = 1.
_ONE_MINUS_EPS = 1.0 - 2.0**-53


# --------------------------------------------------------------------------------------------
# small vector helpers


def dot(a, b):
    return np.sum(np.asarray(a) * np.asarray(b), axis=-1)


def normalize(v):
    """v / |v| along the last axis; 0 stays 0. Scaled by the largest component first, so
    vectors of length 1e-200 (whose squared length underflows) still come out unit."""
    v = np.asarray(v, dtype=np.float64)
    scale = np.max(np.abs(v), axis=-1, keepdims=True)
    v = v / np.where(scale > 0, scale, 1.0)
    norm = np.sqrt(np.sum(v * v, axis=-1, keepdims=True))
    return v / np.where(norm > 0, norm, 1.0)


def luminance(rgb):
    """Rec. 709 luminance of (..., 3) -> (...)."""
    return np.asarray(rgb, dtype=np.float64) @ REC709


def _f64(*arrays):
    return [np.asarray(a, dtype=np.float64) for a in arrays]


def _clamp_ka(ka):
    return np.maximum(np.asarray(ka, dtype=np.float64), KA_MIN)


# --------------------------------------------------------------------------------------------
# local frame: Duff, Burgess, Christensen, Hery, Kensler, Liani, Villemin, "Building an
# Orthonormal Basis, Revisited", JCGT 6(1), 2017, Listing 3 (branchlessONB).


def branchless_onb_scalar(nx: float, ny: float, nz: float):
    """Duff et al. 2017 Listing 3, one normal at a time: the form to mirror in OpenCL C.

        float sign = copysign(1.0f, n.z);
        float a = -1.0f / (sign + n.z);
        float b = n.x * n.y * a;
        b1 = (float3)(1.0f + sign * n.x * n.x * a, sign * b, -sign * n.x);
        b2 = (float3)(b, sign + n.y * n.y * a, -n.y);

    (b1, b2, n) is right-handed: b1 x b2 = n. copysign(1, -0.0) = -1 keeps sign + n.z != 0.
    """
    sign = math.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    b1 = (1.0 + sign * nx * nx * a, sign * b, -sign * nx)
    b2 = (b, sign + ny * ny * a, -ny)
    return b1, b2


def branchless_onb(n):
    """Vectorised `branchless_onb_scalar`: n (..., 3) -> (b1, b2), each (..., 3)."""
    n = np.asarray(n, dtype=np.float64)
    nx, ny, nz = n[..., 0], n[..., 1], n[..., 2]
    sign = np.copysign(1.0, nz)
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    b1 = np.stack([1.0 + sign * nx * nx * a, sign * b, -sign * nx], axis=-1)
    b2 = np.stack([b, sign + ny * ny * a, -ny], axis=-1)
    return b1, b2


def to_world(n, local):
    """Local (x, y, z) in the frame (b1, b2, n) -> world: x b1 + y b2 + z n."""
    n, local = _f64(n, local)
    b1, b2 = branchless_onb(n)
    return local[..., 0:1] * b1 + local[..., 1:2] * b2 + local[..., 2:3] * n


def to_local(n, v):
    """World v -> local (v.b1, v.b2, v.n)."""
    n, v = _f64(n, v)
    b1, b2 = branchless_onb(n)
    return np.stack([dot(v, b1), dot(v, b2), dot(v, n)], axis=-1)


# --------------------------------------------------------------------------------------------
# the three microfacet factors (docs/renderer.md "Material model")


def beckmann_d(n, h, ka):
    """Beckmann NDF with ka = alpha^2, zero for n.h <= 0.

    D = exp(-tan^2 theta_h / ka) / (pi ka cos^4 theta_h)          (Walter et al. 2007, Eq. 25)
    with tan^2 theta_h = |n x h|^2 / (n.h)^2: the cross product keeps tan^2 accurate for tiny
    angles, where 1/(n.h)^2 - 1 would cancel (MILO Eq. 3 writes the exponent as
    ((n.h)^2 - 1) / (ka (n.h)^2), which is the same number).
    """
    n, h = _f64(n, h)
    ka = _clamp_ka(ka)
    ch = dot(n, h)
    up = ch > 0
    ch_s = np.where(up, ch, 1.0)
    sin2 = np.sum(np.cross(n, h) ** 2, axis=-1)
    # ch^2 and ch^4 underflow only when ch < 1e-77, where tan2 / ka > 1e150 and exp() is
    # already 0: the floors turn 0 / 0 into 0 / tiny = 0.
    tan2 = sin2 / np.maximum(ch_s * ch_s, 1e-300)
    ch4 = np.maximum(ch_s**4, 1e-300)
    return np.where(up, np.exp(-tan2 / ka) / (np.pi * ka * ch4), 0.0)


def vcavity_g(ch, co, ci, woh, wih):
    """V-cavity masking-shadowing, Cook and Torrance 1982 / MILO Eq. 3:
    G = min(1, 2 (n.h)(n.wo) / (wo.h), 2 (n.h)(n.wi) / (wi.h)). Callers guarantee wo.h, wi.h > 0.
    """
    return np.minimum(1.0, np.minimum(2.0 * ch * co / woh, 2.0 * ch * ci / wih))


def f90(ks, clamp: bool = True):
    """Schlick's F90: min(1, 50 ks) with the UE4 clamp (Karis 2013), 1 without (MILO Eq. 3)."""
    ks = np.asarray(ks, dtype=np.float64)
    return np.minimum(1.0, F90_SLOPE * ks) if clamp else np.ones_like(ks)


def fresnel_schlick(ks, cos_ih, clamp: bool = True):
    """Schlick 1994 per channel: F = ks + (F90 - ks) (1 - wi.h)^5; ks (..., 3), cos_ih (...)."""
    ks = np.asarray(ks, dtype=np.float64)
    m = np.clip(1.0 - np.asarray(cos_ih, dtype=np.float64), 0.0, 1.0)[..., None] ** 5
    return ks + (f90(ks, clamp) - ks) * m


# --------------------------------------------------------------------------------------------
# the BSDF


def milo_bsdf_cos(n, wo, wi, kd, ks, ka, f90_clamp: bool = True):
    """f(wi, wo) * (n.wi), RGB (..., 3): MILO Eq. 3 in the form of docs/renderer.md.

    f = kd / pi + D(h) F(wi.h) G / (4 ci co)   for ci = n.wi > 0 and co = n.wo > 0, else 0,
    h = normalize(wi + wo) (Walter et al. 2007, Eq. 13 and 20: the 4 ci co denominator).
    The specular part of f ci is evaluated as D F G / (4 co): the same number, without forming
    ci co, which can underflow at grazing angles.
    """
    n, wo, wi, kd, ks = _f64(n, wo, wi, kd, ks)
    ka = _clamp_ka(ka)
    ci, co = dot(n, wi), dot(n, wo)
    valid = (ci > 0) & (co > 0)
    # with ci, co > 0, n.(wi + wo) > 0, so wi + wo != 0 and h is well defined
    h = normalize(wi + wo)
    ch, woh, wih = dot(n, h), dot(wo, h), dot(wi, h)
    ok = valid & (woh > 0) & (wih > 0)
    woh_s, wih_s, co_s = (np.where(ok, x, 1.0) for x in (woh, wih, co))
    d = beckmann_d(n, h, ka)
    g = vcavity_g(ch, co_s, ci, woh_s, wih_s)
    f = fresnel_schlick(ks, wih, f90_clamp)
    spec_cos = (d * g / (4.0 * co_s))[..., None] * f
    diff_cos = kd * (ci / np.pi)[..., None]
    return np.where(valid[..., None], diff_cos + np.where(ok[..., None], spec_cos, 0.0), 0.0)


# --------------------------------------------------------------------------------------------
# strategy 1: cosine-weighted hemisphere (Malley's method, pbrt-v3 13.6.3, polar mapping)


def sample_cosine(n, u1, u2):
    """wi with density max(n.wi, 0) / pi: local (sqrt(u1) cos phi, sqrt(u1) sin phi,
    sqrt(1 - u1)), phi = 2 pi u2 (a uniform disk point lifted to the hemisphere)."""
    n, u1, u2 = _f64(n, u1, u2)
    r = np.sqrt(u1)
    phi = 2.0 * np.pi * u2
    z = np.sqrt(np.maximum(0.0, 1.0 - u1))
    local = np.stack(np.broadcast_arrays(r * np.cos(phi), r * np.sin(phi), z), axis=-1)
    return to_world(n, local)


def pdf_cosine(n, wi):
    """max(n.wi, 0) / pi (docs strategy 1)."""
    return np.maximum(dot(*_f64(n, wi)), 0.0) / np.pi


# --------------------------------------------------------------------------------------------
# strategy 2: Beckmann half-vector sampling (Walter et al. 2007, Eq. 28-29, 14, 17)


def sample_beckmann_h(n, ka, u1, u2):
    """Half vector h with density D(h) (n.h) over solid angle (Walter et al. 2007 Eq. 28):
    tan^2 theta_h = -ka ln(1 - u1) (as -ka log1p(-u1)), phi_h = 2 pi u2; local
    h = (sin cos phi, sin sin phi, cos) with cos = 1 / sqrt(1 + tan^2), sin = sqrt(tan^2 / (1 + tan^2)).
    """
    n, u1, u2 = _f64(n, u1, u2)
    ka = _clamp_ka(ka)
    tan2 = -ka * np.log1p(-np.minimum(u1, _ONE_MINUS_EPS))
    cos_t = 1.0 / np.sqrt(1.0 + tan2)
    sin_t = np.sqrt(tan2 / (1.0 + tan2))
    phi = 2.0 * np.pi * u2
    local = np.stack(np.broadcast_arrays(sin_t * np.cos(phi), sin_t * np.sin(phi), cos_t), axis=-1)
    return to_world(n, local)


def reflect(wo, h):
    """Mirror wo about h: 2 (wo.h) h - wo (Walter et al. 2007 Eq. 14)."""
    wo, h = _f64(wo, h)
    return 2.0 * dot(wo, h)[..., None] * h - wo


def sample_specular(n, wo, ka, u1, u2):
    """wi = reflect(wo, h), h from `sample_beckmann_h`. wi may point below the surface
    (n.wi <= 0): the sample then carries f = 0 and `pdf_specular` is 0 there."""
    n, wo = _f64(n, wo)
    h = sample_beckmann_h(n, ka, u1, u2)
    return reflect(wo, h)


def pdf_specular(n, wo, wi, ka):
    """Solid-angle density of `sample_specular`: D(h) (n.h) / (4 |wo.h|) (Walter et al. 2007
    Eq. 14 and 17: d(omega_h) / d(omega_i) = 1 / (4 |wo.h|)), zero if n.wi <= 0.

    h = normalize(wi + wo), turned into the upper hemisphere (the sampler only draws n.h > 0;
    h and -h reflect wo to the same wi). For co > 0 and ci > 0 the turn never happens.
    """
    n, wo, wi = _f64(n, wo, wi)
    s = wi + wo
    norm = np.linalg.norm(s, axis=-1)
    h = s / np.where(norm > 0, norm, 1.0)[..., None]
    h = h * np.where(dot(n, h) < 0, -1.0, 1.0)[..., None]
    ch = dot(n, h)
    woh = np.abs(dot(wo, h))
    ok = (dot(n, wi) > 0) & (norm > 0) & (woh > 0)
    return np.where(ok, beckmann_d(n, h, ka) * ch / (4.0 * np.where(ok, woh, 1.0)), 0.0)


# --------------------------------------------------------------------------------------------
# directional albedo by deterministic quadrature


@functools.lru_cache(maxsize=16)
def gauss_legendre01(n: int):
    """n-point Gauss-Legendre nodes and weights on [0, 1], by Newton's method on P_n with the
    three-term recurrence (Numerical Recipes 3rd ed., 4.6.1 gauleg): no eigensolver, so no
    BLAS threads (numpy's leggauss can take seconds inside a busy test process)."""
    i = np.arange(1, n + 1)
    x = np.cos(np.pi * (i - 0.25) / (n + 0.5))  # initial guesses, descending roots
    for _ in range(100):
        p0, p1 = np.ones_like(x), x.copy()
        for k in range(2, n + 1):  # P_k = ((2k - 1) x P_{k-1} - (k - 1) P_{k-2}) / k
            p0, p1 = p1, ((2 * k - 1) * x * p1 - (k - 1) * p0) / k
        dp = n * (x * p1 - p0) / (x * x - 1.0)  # P_n'
        step = p1 / dp
        x = x - step
        if np.abs(step).max() < 1e-15:
            break
    w = 2.0 / ((1.0 - x * x) * dp * dp)
    return 0.5 * (1.0 - x), 0.5 * w  # ascending nodes on [0, 1]


def specular_albedo_terms(theta_o, ka, n: int = 128, m: int = 8):
    """(A1, A2) with  integral of the specular part of f ci over wi  =  ks A1 + F90 A2.

    Schlick's F = ks (1 - (1 - c)^5) + F90 (1 - c)^5 is affine in (ks, F90), so
        A1 = int D G (1 - (1 - c)^5) / (4 co) d(omega_i),   A2 = int D G (1 - c)^5 / (4 co) d(omega_i),
    c = wo.h = wi.h. Both are computed in the variables of the Beckmann sampler: with
    d(omega_i) = 4 c d(omega_h) and D (n.h) d(omega_h) = du1 du2,
        int D F G / (4 co) d(omega_i) = int_[0,1]^2 F G c / (co ch) [n.wi > 0] du1 du2,
    and G c / (co ch) = min(c / (co ch), 2, 2 ci / co). The map concentrates the nodes on the
    specular peak at any roughness (the "adaptivity" for small ka is exact), and the integrand
    is bounded (<= 2) and continuous (G -> 0 at the horizon).

    Its kinks are placed exactly: in the local frame (n = z, wo = (so, 0, co)) and for a fixed
    u1 (so fixed theta_h, sh = sin, ch = cos), c = so sh cos(phi) + co ch and
    ci = 2 c ch - co are affine in cos(phi), so every switch of the min and the horizon are
    at known phi:  ci = 0,  ci = co (2 ci / co = 2),  c = 2 co ch (c / (co ch) = 2),  and
    2 ch ci = c (the two ratios equal). phi in [0, pi] (the integrand is even in phi) is split
    there and each piece gets m-point Gauss-Legendre, which is then spectrally accurate; u1
    gets n-point Gauss-Legendre. Defaults agree with (n, m) = (1024, 64) to < 1e-4 for ka in
    [1e-6, 1] and all angles (tests/render/test_reference.py), including the nearly grazing
    wo where the 2 ci / co ramp is only co wide.
    The integrand has the finite limit 2F[ci > 0] as co -> 0, so theta_o = 90 degrees returns
    the grazing limit (the sup over angles; f itself is 0 at exactly co = 0).

    theta_o and ka broadcast; returns two arrays of their broadcast shape.
    """
    theta_o, ka = np.broadcast_arrays(*_f64(theta_o, ka))
    ka = _clamp_ka(ka)
    u1, w1 = gauss_legendre01(n)
    xg, wg = gauss_legendre01(m)
    log1m = np.log1p(-u1)[:, None]
    flat_t, flat_k = theta_o.ravel(), ka.ravel()
    a1, a2 = np.empty(flat_t.shape), np.empty(flat_t.shape)
    for k in np.unique(flat_k):  # one (u1, theta, phi) block per roughness
        sel = np.flatnonzero(flat_k == k)
        th = flat_t[sel][None, :]
        co, so = np.maximum(np.cos(th), 0.0), np.sin(th)  # local frame: n = z, wo = (so, 0, co)
        tan2 = -k * log1m  # the sampler's map (u1, u2) -> h
        ch = 1.0 / np.sqrt(1.0 + tan2)
        sh = np.sqrt(tan2 / (1.0 + tan2))
        a = so * sh  # c = a cos(phi) + co ch
        with np.errstate(divide="ignore", invalid="ignore"):
            x_breaks = [  # cos(phi) at the kinks (see above); inf / nan ones fall outside
                -co * (2.0 * ch * ch - 1.0) / (2.0 * ch * a),  # ci = 0
                co * sh / (ch * so),  # ci = co
                co * ch / a,  # c = 2 co ch
                co * ch * (3.0 - 4.0 * ch * ch) / (a * (4.0 * ch * ch - 1.0)),  # 2 ch ci = c
            ]
        phi_breaks = [np.arccos(np.clip(np.nan_to_num(x, nan=1.0), -1.0, 1.0)) for x in x_breaks]
        edges = np.sort(
            np.stack(np.broadcast_arrays(np.zeros_like(a), *phi_breaks, np.full_like(a, np.pi)), axis=-1), axis=-1
        )
        lo, width = edges[..., :-1, None], np.diff(edges, axis=-1)[..., None]
        phi = lo + width * xg  # (n, theta, piece, m)
        wphi = width * wg  # the weights of phi / pi are width * wg / pi
        co4, ch4, a4 = co[..., None, None], ch[..., None, None], a[..., None, None]
        c = a4 * np.cos(phi) + co4 * ch4  # wo.h
        ci = 2.0 * c * ch4 - co4  # n.wi for wi = 2 c h - wo
        ok = (ci > 0) & (c > 0)
        with np.errstate(divide="ignore", invalid="ignore"):
            g_ratio = np.minimum(2.0, np.minimum(c / (co4 * ch4), 2.0 * ci / co4))  # G c / (co ch)
        g_ratio = np.where(ok, g_ratio, 0.0)
        m5 = np.clip(1.0 - c, 0.0, 1.0) ** 5
        # u2 = phi / (2 pi) over [0, 1] = (phi / pi) over [0, pi] by symmetry
        a1[sel] = np.einsum("i,ijpq->j", w1, wphi * g_ratio * (1.0 - m5)) / np.pi
        a2[sel] = np.einsum("i,ijpq->j", w1, wphi * g_ratio * m5) / np.pi
    return a1.reshape(theta_o.shape), a2.reshape(theta_o.shape)


def directional_albedo(theta_o, kd, ks, ka, n: int = 128, f90_clamp: bool = True):
    """Integral over the hemisphere of f(wi, wo) (n.wi) d(omega_i), RGB, for wo at polar angle
    theta_o (radians). The diffuse lobe integrates to kd exactly; the specular lobe is
    ks A1 + F90 A2 from `specular_albedo_terms`. theta_o, ka (...) and kd, ks (..., 3) broadcast.
    """
    kd, ks = _f64(kd, ks)
    a1, a2 = specular_albedo_terms(theta_o, ka, n)
    return kd + ks * a1[..., None] + f90(ks, f90_clamp) * a2[..., None]


# --------------------------------------------------------------------------------------------
# an upper bound of the albedo over all incidence angles, for choosing the number of bounces

# Table grids. theta: denser towards grazing, where the specular albedo changes fastest and
# (for ks < 1) takes its maximum. ka: 8 nodes per decade over the model's range. ks: a node at
# the F90 kink 0.02, so each piece [0, 0.02] and [0.02, 1] is covered by nodes.
TABLE_THETA = 0.5 * np.pi * (1.0 - (1.0 - np.linspace(0.0, 1.0, 48)) ** 2)
TABLE_KA = np.logspace(-6.0, 0.0, 49)
TABLE_KS = np.array(
    [
        0.0,
        0.0025,
        0.005,
        0.0075,
        0.01,
        0.0125,
        0.015,
        0.0175,
        0.02,
        0.03,
        0.05,
        0.075,
        0.1,
        0.15,
        0.2,
        0.3,
        0.4,
        0.5,
        0.6,
        0.7,
        0.8,
        0.9,
        1.0,
    ]
)
# Added to every bound: covers the quadrature error (< 1e-4 at n = 128) and the excess of the
# true function between table nodes over the node values (measured 2e-16 on a 4x finer
# (ka, theta) grid; tests/render/test_reference.py::test_max_albedo_is_an_upper_bound).
ALBEDO_BOUND_MARGIN = 2e-3


@functools.lru_cache(maxsize=2)
def albedo_bound_tables(f90_clamp: bool = True, n: int = 128):
    """Precomputed tables behind `max_albedo` (about 1 s, computed once per process).

    Returns a dict with
      ka, ks, theta:  the grids (TABLE_KA, TABLE_KS, TABLE_THETA),
      a1, a2:         (len(ka), len(theta)) from `specular_albedo_terms`,
      spec_max:       (len(ka), len(ks)): max over theta nodes of ks A1 + F90(ks) A2, then made
                      nonincreasing in ka by a running max from the rough end.
    """
    theta, ka, ks = TABLE_THETA, TABLE_KA, TABLE_KS
    a1, a2 = specular_albedo_terms(theta[None, :], ka[:, None], n)
    spec = ks[None, :, None] * a1[:, None, :] + f90(ks, f90_clamp)[None, :, None] * a2[:, None, :]
    run_max = lambda t: np.maximum.accumulate(t[::-1], axis=0)[::-1]  # max over ka' >= ka
    return {
        "ka": ka,
        "ks": ks,
        "theta": theta,
        "a1": a1,
        "a2": a2,
        "spec_max": run_max(spec.max(axis=2)),
    }


def max_albedo(kd, ks, ka, f90_clamp: bool = True):
    """Upper bound over all incidence angles of `directional_albedo`, per channel: kd (..., 3),
    ks (..., 3), ka (...) -> (..., 3). Vectorised over any number of texels.

    Why it is an upper bound:
    - diffuse: the cosine lobe integrates to kd exactly, at every angle.
    - ks: at fixed (ka, theta) the specular albedo ks A1 + min(1, 50 ks) A2 is affine in ks on
      [0, 0.02] and on [0.02, inf) (A1, A2 >= 0). The max over theta of affine functions is
      convex on each piece, so the chord between two ks nodes of the same piece lies above it:
      linear interpolation in ks between nodes (0.02 is a node) never underestimates.
      Beyond ks = 1 (F90 = 1), ks A1 + A2 <= ks (A1 + A2), so ks times the ks = 1 entry.
      ks < 0 is treated as 0 (the specular term is then <= 0).
    - ka: the table row used is the node at or below ka, after a running max over all rougher
      nodes, so it bounds every node >= ka. Between nodes the maximum over angles decreases
      with roughness (for ks < 1 it is the grazing limit, which shrinks as ka grows), and the
      excess measured between nodes is inside ALBEDO_BOUND_MARGIN. ka > 1 uses the ka = 1 row.
    - theta: the max over theta nodes includes the grazing limit theta = 90 degrees (where the
      maximum is for ks < 1); the excess between nodes is inside ALBEDO_BOUND_MARGIN.
    """
    kd, ks = _f64(kd, ks)
    ka = _clamp_ka(ka)
    t = albedo_bound_tables(f90_clamp)
    # row: last ka node <= ka (ka >= KA_MIN = TABLE_KA[0] after the clamp)
    row = np.clip(np.searchsorted(t["ka"], ka * (1.0 + 1e-12), side="right") - 1, 0, len(t["ka"]) - 1)[..., None]
    ks_c = np.clip(ks, 0.0, 1.0)
    j = np.clip(np.searchsorted(t["ks"], ks_c, side="right") - 1, 0, len(t["ks"]) - 2)
    k0, k1 = t["ks"][j], t["ks"][j + 1]
    w = (ks_c - k0) / (k1 - k0)
    row_b, j = np.broadcast_arrays(row, j)
    ks_c, w, ks = np.broadcast_arrays(ks_c, w, ks)
    spec = (1.0 - w) * t["spec_max"][row_b, j] + w * t["spec_max"][row_b, j + 1]
    beyond = ks * t["spec_max"][row_b, -1]  # ks > 1: ks A1 + A2 <= ks (A1 + A2), F90 = 1
    spec = np.where(ks > 1.0, beyond, spec)
    return kd + spec + ALBEDO_BOUND_MARGIN

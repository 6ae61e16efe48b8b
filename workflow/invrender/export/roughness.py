"""Our roughness ka (Beckmann alpha^2) <-> UsdPreviewSurface `roughness`, and what the mapping costs.

UsdPreviewSurface's roughness r is "usually squared before use with a GGX or Beckmann lobe"
(its specification), and the renderers that implement it (Hydra Storm, RenderMan, Karma,
Omniverse) use GGX with alpha = r^2. Our lobe is Beckmann with alpha^2 = ka (docs/renderer.md),
so the mapping keeps alpha:

    r = ka^(1/4)        ka = r^4

The two distributions agree at the peak for small alpha and differ in the tails (GGX's are
long), and the two shadowing terms (our V-cavity, GGX's Smith) differ at grazing angles. This
module measures that difference by quadrature, independent of any renderer:
`python -m invrender.export.roughness` prints the table quoted in docs/export.md.
"""

from __future__ import annotations

import numpy as np

__all__ = ["roughness_from_ka", "ka_from_roughness", "KA_MIN", "lobes", "mapping_error", "main"]

KA_MIN = 1e-6  # the model's lowest roughness (render/bsdf.py clamps ka there too)


def roughness_from_ka(ka):
    """UsdPreviewSurface roughness r = ka^(1/4), float32 like the texture that holds it."""
    return np.power(np.asarray(ka, np.float64), 0.25).astype(np.float32)


def ka_from_roughness(r):
    """ka = r^4, clamped to the model's range (KA_MIN, 1]."""
    r = np.clip(np.asarray(r, np.float64), 0.0, 1.0)
    return np.clip(r**4, KA_MIN, 1.0).astype(np.float32)


def _half_vector_grid(alpha: float, n_theta: int, n_phi: int):
    """Quadrature nodes over the hemisphere of half vectors: tan(theta_h) = alpha tan(pi/2 s) for s
    uniform, so the nodes crowd where either lobe has its mass. Returns (h (k, 3), weight (k,))
    with sum(weight g(h)) ~ integral of g over solid angle."""
    s = (np.arange(n_theta) + 0.5) / n_theta
    tan_h = alpha * np.tan(0.5 * np.pi * s)
    theta = np.arctan(tan_h)
    dtheta = alpha * 0.5 * np.pi / np.cos(0.5 * np.pi * s) ** 2 / (1.0 + tan_h**2) / n_theta
    phi = (np.arange(n_phi) + 0.5) / n_phi * 2.0 * np.pi
    theta, phi = np.meshgrid(theta, phi, indexing="ij")
    h = np.stack([np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi), np.cos(theta)], -1).reshape(-1, 3)
    weight = (np.sin(theta) * dtheta[:, None] * (2.0 * np.pi / n_phi)).reshape(-1)
    return h, weight


def beckmann_d(cos_h, alpha):
    """Beckmann D with alpha (ours: ka = alpha^2), through tan^2 as docs/renderer.md writes it."""
    c2 = cos_h**2
    tan2 = (1.0 - c2) / c2
    return np.exp(-tan2 / alpha**2) / (np.pi * alpha**2 * c2**2)


def ggx_d(cos_h, alpha):
    a2 = alpha**2
    return a2 / (np.pi * (cos_h**2 * (a2 - 1.0) + 1.0) ** 2)


def smith_ggx_g1(cos_v, alpha):
    tan2 = (1.0 - cos_v**2) / cos_v**2
    return 2.0 / (1.0 + np.sqrt(1.0 + alpha**2 * tan2))


def lobes(ka: float, theta_o: float, n_theta: int = 1024, n_phi: int = 512):
    """Our specular lobe (Beckmann, V-cavity G) and UsdPreviewSurface's (GGX alpha = r^2, separable
    Smith G) at the mapped roughness, both f cos(theta_i) with F = 1, on a half-vector quadrature
    seen from theta_o: (ours (k,), theirs (k,), solid-angle weight of each wi (k,))."""
    alpha_ours = np.sqrt(ka)
    alpha_theirs = float(roughness_from_ka(ka)) ** 2
    wo = np.array([np.sin(theta_o), 0.0, np.cos(theta_o)])
    h, weight_h = _half_vector_grid(max(alpha_ours, alpha_theirs), n_theta, n_phi)
    wo_h = h @ wo
    wi = 2.0 * wo_h[:, None] * h - wo
    ci, co, ch = wi[:, 2], wo[2], h[:, 2]
    valid = (ci > 0) & (wo_h > 0)
    weight = np.where(valid, weight_h * 4.0 * np.abs(wo_h), 0.0)  # d omega_i = 4 |wo.h| d omega_h
    ci, wo_h = np.where(valid, ci, 1.0), np.where(valid, wo_h, 1.0)
    g_vcavity = np.minimum(1.0, np.minimum(2.0 * ch * co / wo_h, 2.0 * ch * ci / wo_h))
    ours = beckmann_d(ch, alpha_ours) * g_vcavity / (4.0 * co)  # D G / (4 ci co) * ci
    theirs = ggx_d(ch, alpha_theirs) * smith_ggx_g1(ci, alpha_theirs) * smith_ggx_g1(co, alpha_theirs) / (4.0 * co)
    return np.where(valid, ours, 0.0), np.where(valid, theirs, 0.0), weight


def mapping_error(ka: float, theta_o: float) -> dict:
    """Directional albedo of both lobes (F = 1) and their relative L1 difference
    integral |f_ours - f_theirs| cos / integral f_ours cos, at one view angle."""
    ours, theirs, weight = lobes(ka, theta_o)
    albedo_ours, albedo_theirs = float(ours @ weight), float(theirs @ weight)
    return {
        "ka": ka,
        "theta_o_deg": float(np.degrees(theta_o)),
        "albedo_ours": albedo_ours,
        "albedo_usd": albedo_theirs,
        "lobe_l1": float(np.abs(ours - theirs) @ weight / albedo_ours),
    }


KA_TABLE = (0.001, 0.01, 0.02, 0.05, 0.1, 0.3, 1.0)
ANGLES_DEG = (0.0, 30.0, 60.0, 80.0)


def main() -> None:
    print("| ka | r = ka^(1/4) | view angle | albedo, ours (Beckmann, V-cavity) | albedo, GGX + Smith | lobe L1 |")
    print("|---|---|---|---|---|---|")
    for ka in KA_TABLE:
        for angle in ANGLES_DEG:
            e = mapping_error(ka, np.radians(angle))
            print(
                f"| {ka:g} | {float(roughness_from_ka(ka)):.3f} | {angle:.0f} deg | {e['albedo_ours']:.3f} "
                f"| {e['albedo_usd']:.3f} | {e['lobe_l1']:.2f} |"
            )


if __name__ == "__main__":
    main()

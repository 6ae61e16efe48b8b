"""Which effects a scene calls for: the one place that decides the kernels' build flags.

The `features` stage (``features/stage.py``) writes the answer with its evidence as
features.json; synthesis and the tools call ``analyse`` directly. Each decision is a number
from the scene (largest ks, emitting triangles, whether rays escape, the largest albedo), so the
evidence says why an effect was compiled in or out.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

from .features import Features


@dataclass(frozen=True)
class AnalysisSettings:
    """How the features stage decides (config key `features:`)."""

    specular_threshold: float = 1e-3  # largest ks at or below which the lobe is compiled out
    bounce_fraction: float = 0.01  # power beyond the last bounce, relative to all power
    max_bounces: int = 10
    min_bounces: int = 1
    # Russian roulette from this vertex on when paths are longer (0: never). On the benchmark room
    # at B = 10 it cut the time per sample 2.4x for the same variance (docs/benchmarks.md).
    roulette_depth: int = 3


def bounces_for(rho: float, settings: AnalysisSettings) -> int:
    """Smallest B whose tail bound rho^(B+1) / (1 - rho) is at most the fraction.

    Each bounce multiplies the power leaving the surfaces by at most rho, the largest directional
    albedo of any texel (an upper bound over all incidence angles, render/bsdf.max_albedo), so the
    power carried by bounces > B is at most P_0 rho^(B+1) / (1 - rho), P_0 <= all power.
    """
    if rho >= 1.0:
        return settings.max_bounces
    for bounces in range(settings.min_bounces, settings.max_bounces + 1):
        if rho ** (bounces + 1) / (1.0 - rho) <= settings.bounce_fraction:
            return bounces
    return settings.max_bounces


def preview_camera(camera, max_width: int = 48):
    """The same view at a small resolution (intrinsics scaled with the image)."""
    from ..scene.types import Camera

    scale = min(1.0, max_width / camera.width)
    params = np.array(camera.params, np.float64)
    params[: 4 if camera.model != "SIMPLE_PINHOLE" else 3] *= scale
    return Camera(
        camera.name,
        camera.model,
        max(1, round(camera.width * scale)),
        max(1, round(camera.height * scale)),
        params,
        camera.R,
        camera.t,
    )


def rays_can_escape(scene, bounces: int = 3, spp: int = 4, device: str | None = None) -> bool:
    """Whether paths from the cameras reach the space outside the mesh (and so see kg) within a
    few bounces: rendered, not guessed from the mesh, since an open lamp quad inside a closed
    room is no way out while a closed object seen from around it is. A white scene under a white
    sky and no other light: any radiance at all is light that came from outside. A hole smaller
    than the preview's sampling can be missed; windows count through kw, not here. Without
    cameras nothing is known: assume rays escape."""
    if not scene.cameras:
        return True
    from ..scene.types import Maps, Scene
    from .renderer import Renderer  # the escape probe renders; renderer imports features only

    probe = Scene(scene.mesh, Maps.uniform(size=(1, 1), kd=1.0, ks=0.0, kg=1.0, cube=1), scene.cameras)
    features = Features.only(max_bounces=bounces, environment=True)
    renderer = Renderer(probe, features, device=device)
    return any(renderer.render(preview_camera(c), spp=spp, aovs=False)["radiance"].max() > 0 for c in scene.cameras)


def has_one_sided_emitters(mesh, maps) -> bool:
    """Whether some face that emits (ke, or a window's kw kg) is one-sided, the condition for
    FEATURE_ONE_SIDED: without one, every face emits on both sides and the check is compiled out."""
    from .scene_buffers import emitted_power, one_sided_faces

    one_sided = one_sided_faces(mesh)
    if not one_sided.any():
        return False
    return bool(maps.kw.max() > 0 or np.any(one_sided & (emitted_power(mesh, maps) > 0)))


def unphysical_albedo(maps) -> str | None:
    """One line naming the map and the texel with the largest directional albedo at normal
    incidence, if it is above 1 (a surface reflecting more light than it receives), else None.

    Normal incidence, not render/bsdf.max_albedo's bound over all angles: MILO's model sums the
    lobes without energy conservation, so towards grazing even kd 0.9, ks 0.04 exceeds 1 (1.4),
    and a warning on every ordinary material says nothing. ks = 1 with kd 0.8 is 1.8 at normal
    incidence: that is the input a user mistyped."""
    from .bsdf import KA_MIN, f90, specular_albedo_terms

    # The lobe's terms on 64 roughness nodes, each texel taking the node at or below its ka (a
    # smoother lobe reflects more): a 1024^2 atlas of distinct ka in a tenth of a second.
    ka_nodes = np.geomspace(KA_MIN, 1.0, 64)
    node = np.clip(np.searchsorted(ka_nodes, np.asarray(maps.ka, np.float64), side="right") - 1, 0, 63)
    a1, a2 = (a[node][..., None] for a in specular_albedo_terms(0.0, ka_nodes))
    kd, ks = np.asarray(maps.kd, np.float64), np.asarray(maps.ks, np.float64)
    rho = (kd + ks * a1 + f90(ks) * a2).max(axis=-1)
    y, x = np.unravel_index(int(np.argmax(rho)), rho.shape)
    if not rho[y, x] > 1.0:
        return None
    culprit = "kd" if kd[y, x].max() > 1.0 else "ks"
    return (
        f"map {culprit}: texel (x {x}, y {y}) reflects more light than it receives: directional albedo "
        f"{rho[y, x]:.3g} > 1 at normal incidence (kd {np.round(kd[y, x], 3).tolist()}, "
        f"ks {np.round(ks[y, x], 3).tolist()}, ka {float(maps.ka[y, x]):.3g}; {int((rho > 1).sum())} such texels)"
    )


def warn_unphysical_albedo(maps, where, log) -> None:
    """A scene that creates energy still renders (an optimiser may pass through one): one
    warning line, naming ``where`` (the scene) and the texel."""
    problem = unphysical_albedo(maps)
    if problem:
        log.warning("%s: %s", where, problem)


def analyse_scene(
    scene, settings: AnalysisSettings = AnalysisSettings(), overrides: dict | None = None, device: str | None = None
):
    """(Features, evidence): the effects `scene` calls for, and the numbers behind each choice."""
    from .bsdf import max_albedo
    from .scene_buffers import emitted_power
    from .tuning import choose_strategy_weights

    maps = scene.maps
    max_ks = float(maps.ks.max())
    specular = max_ks > settings.specular_threshold
    emitting_triangles = int(np.count_nonzero(emitted_power(scene.mesh, maps) > 0))
    emission = bool(maps.ke.max() > 0)
    sky = bool(maps.kg.max() > 0)
    window = sky and bool(maps.kw.max() > 0)
    escape = sky and rays_can_escape(scene, device=device)
    environment = sky and (window or escape)
    ks_effective = maps.ks if specular else np.zeros_like(maps.ks)
    rho = float(max_albedo(maps.kd, ks_effective, maps.ka).max())
    features = Features(
        specular=specular,
        emission=emission,
        emitter_sampling=emitting_triangles > 0,
        environment=environment,
        window=window and environment,
        env_sampling=environment,
        one_sided=has_one_sided_emitters(scene.mesh, maps),
        max_bounces=(bounces := bounces_for(rho, settings)),
        roulette_depth=settings.roulette_depth if bounces > settings.roulette_depth else 0,
    ).with_overrides(overrides)
    tuning = None
    if not {"w_env", "w_emit"} & set(overrides or {}):
        features, tuning = choose_strategy_weights(scene, features, device)
    evidence = {
        "max_ks": max_ks,
        "emitting_triangles": emitting_triangles,
        "max_ke": float(maps.ke.max()),
        "max_kw": float(maps.kw.max()),
        "max_kg": float(maps.kg.max()),
        "rays_can_escape": escape,
        "max_albedo": rho,
        "tail_bound": (rho ** (features.max_bounces + 1) / (1 - rho)) if rho < 1 else None,
        "strategy_weights": tuning,
        "settings": asdict(settings),
        "overrides": overrides or {},
    }
    return features, evidence


def analyse(
    scene, settings: AnalysisSettings = AnalysisSettings(), overrides: dict | None = None, device: str | None = None
) -> Features:
    return analyse_scene(scene, settings, overrides, device)[0]

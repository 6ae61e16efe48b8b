"""Which effects a scene calls for, decided once and compiled into the kernels.

The `features` stage writes this as features.json; the kernels are built with exactly these
defines (Cycles' KERNEL_FEATURE_* habit), so an effect a scene lacks costs nothing.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields, replace

import numpy as np

FORMAT_VERSION = 1


@dataclass(frozen=True)
class Features:
    specular: bool = True  # Cook-Torrance lobe (else Lambertian)
    emission: bool = True  # ke term
    emitter_sampling: bool = True  # sampling strategy 4 (emitting triangles)
    environment: bool = True  # kg seen by rays leaving the scene
    window: bool = True  # kw kg on surfaces
    env_sampling: bool = True  # sampling strategy 3 (kg by luminance)
    max_bounces: int = 10

    def __post_init__(self):
        if self.window and not self.environment:
            raise ValueError("features: window needs environment")
        if self.env_sampling and not self.environment:
            raise ValueError("features: env_sampling needs environment")
        if not 0 <= self.max_bounces <= 64:
            raise ValueError(f"features: max_bounces: expected 0..64, got {self.max_bounces}")

    @classmethod
    def everything(cls, max_bounces: int = 10) -> "Features":
        return cls(max_bounces=max_bounces)

    def defines(self) -> tuple[str, ...]:
        flags = [f"-D FEATURE_{f.name.upper()}" for f in fields(self) if f.type in (bool, "bool") and getattr(self, f.name)]
        return tuple(flags + [f"-D MAX_BOUNCES={self.max_bounces}"])

    def with_overrides(self, overrides: dict | None) -> "Features":
        return replace(self, **(overrides or {}))

    def to_json(self) -> dict:
        return {"version": FORMAT_VERSION, "features": asdict(self)}

    @classmethod
    def from_json(cls, data: dict) -> "Features":
        return cls(**data["features"])

    @classmethod
    def read(cls, path) -> "Features":
        with open(path) as handle:
            return cls.from_json(json.load(handle))


@dataclass(frozen=True)
class AnalysisSettings:
    """How the features stage decides (config key `features:`)."""

    specular_threshold: float = 1e-3  # largest ks at or below which the lobe is compiled out
    bounce_fraction: float = 0.01  # power beyond the last bounce, relative to all power
    max_bounces: int = 10
    min_bounces: int = 1


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


def is_open(mesh) -> bool:
    """True if some edge borders one face only (positions welded, so UV seams do not count):
    rays can then leave the scene and see kg."""
    _, welded = np.unique(np.round(mesh.positions.astype(np.float64), 7), axis=0, return_inverse=True)
    faces = welded.reshape(-1)[mesh.faces]
    edges = np.sort(np.concatenate([faces[:, [0, 1]], faces[:, [1, 2]], faces[:, [2, 0]]]), axis=1)
    edges = edges[edges[:, 0] != edges[:, 1]]
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(np.any(counts == 1))


def crossings(mesh, origin, direction) -> int:
    """How many triangles the ray origin + s direction (s > 0) crosses (Moeller-Trumbore, float64)."""
    v0, v1, v2 = (mesh.positions[mesh.faces[:, k]].astype(np.float64) for k in range(3))
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(direction, e2)
    det = np.einsum("ij,ij->i", e1, p)
    ok = np.abs(det) > 1e-300
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - v0
    u = np.einsum("ij,ij->i", s, p) * inv
    q = np.cross(s, e1)
    v = (q @ direction) * inv
    t = np.einsum("ij,ij->i", e2, q) * inv
    return int(np.count_nonzero(ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)))


def encloses(mesh, point) -> bool:
    """Parity of crossings along three fixed, irrational directions; the majority decides, so a
    ray through an edge cannot flip the answer."""
    directions = np.array([[0.5773, 0.5774, 0.5774], [-0.2673, 0.8018, -0.5345], [0.8729, -0.2182, 0.4364]])
    odd = sum(crossings(mesh, np.asarray(point, np.float64), d / np.linalg.norm(d)) % 2 for d in directions)
    return odd >= 2


def rays_can_escape(scene) -> bool:
    """Rays reach kg from outside the mesh when the mesh has a border, or when a camera stands
    outside it (an object seen from around it). A camera inside a closed room sees kg only
    through windows. No cameras: assume the worst."""
    if is_open(scene.mesh) or not scene.cameras:
        return True
    return not all(encloses(scene.mesh, camera.center) for camera in scene.cameras)


def analyse_scene(scene, settings: AnalysisSettings = AnalysisSettings(), overrides: dict | None = None):
    """(Features, evidence): the effects `scene` calls for, and the numbers behind each choice."""
    from .bsdf import max_albedo
    from .scene_buffers import emitted_power

    maps = scene.maps
    max_ks = float(maps.ks.max())
    specular = max_ks > settings.specular_threshold
    emitting_triangles = int(np.count_nonzero(emitted_power(scene.mesh, maps) > 0))
    emission = bool(maps.ke.max() > 0)
    sky = bool(maps.kg.max() > 0)
    window = sky and bool(maps.kw.max() > 0)
    escape = rays_can_escape(scene)
    environment = sky and (window or escape)
    ks_effective = maps.ks if specular else np.zeros_like(maps.ks)
    rho = float(max_albedo(maps.kd, ks_effective, maps.ka).max())
    features = Features(
        specular=specular, emission=emission, emitter_sampling=emitting_triangles > 0,
        environment=environment, window=window and environment, env_sampling=environment,
        max_bounces=bounces_for(rho, settings),
    ).with_overrides(overrides)
    evidence = {
        "max_ks": max_ks, "emitting_triangles": emitting_triangles, "max_ke": float(maps.ke.max()),
        "max_kw": float(maps.kw.max()), "max_kg": float(maps.kg.max()), "rays_can_escape": escape,
        "max_albedo": rho, "tail_bound": (rho ** (features.max_bounces + 1) / (1 - rho)) if rho < 1 else None,
        "settings": asdict(settings), "overrides": overrides or {},
    }
    return features, evidence


def analyse(scene, settings: AnalysisSettings = AnalysisSettings(), overrides: dict | None = None) -> Features:
    return analyse_scene(scene, settings, overrides)[0]

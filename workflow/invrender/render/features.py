"""The effects a kernel build contains: one flag per effect, compiled in or out.

The renderer is built with exactly these defines (Cycles' KERNEL_FEATURE_* habit), so an effect a
scene lacks costs nothing. Which effects a scene calls for is decided in one place,
``render/analysis.py`` (the `features` stage writes its answer as features.json); the renderer
never decides on its own.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass, fields, replace

FORMAT_VERSION = 1


@dataclass(frozen=True)
class Features:
    specular: bool = True  # Cook-Torrance lobe (else Lambertian)
    emission: bool = True  # ke term
    emitter_sampling: bool = True  # sampling strategy 4 (emitting triangles)
    environment: bool = True  # kg seen by rays leaving the scene
    window: bool = True  # kw kg on surfaces
    env_sampling: bool = True  # sampling strategy 3 (kg by luminance)
    # Some emitting faces emit on their front side only (Mesh.one_sided). Off unless asked for,
    # so a features.json from before it means what it meant: every face two-sided.
    one_sided: bool = False
    # Next-event estimation with MIS (kernels/nee.h): a light sample at every vertex beside the
    # BSDF sample. Off: MILO's one-sample mixture of the four strategies (the paper's estimator).
    # Both converge to the same image; docs/benchmarks.md says which wins where.
    nee: bool = True
    max_bounces: int = 10
    # Russian roulette from this vertex on (Mitsuba's rr_depth); 0: off, every path runs to
    # max_bounces (or until it leaves or meets a black texel).
    roulette_depth: int = 0
    # Not build flags but run-time weights of the two light strategies: in MILO's mixture their
    # shares of the one sample (the BSDF lobes get 1 - w_env - w_emit); with nee, only their ratio
    # counts: the share of light samples that go to the sky. render/tuning.py picks them per scene.
    w_env: float = 0.25
    w_emit: float = 0.25

    def __post_init__(self):
        if self.window and not self.environment:
            raise ValueError("features: window needs environment")
        if self.env_sampling and not self.environment:
            raise ValueError("features: env_sampling needs environment")
        if not 0 <= self.max_bounces <= 64:
            raise ValueError(f"features: max_bounces: expected 0..64, got {self.max_bounces}")
        if not (self.w_env >= 0 and self.w_emit >= 0 and self.w_env + self.w_emit <= 1):
            raise ValueError(f"features: w_env, w_emit: expected >= 0 with a sum <= 1, got {self.w_env}, {self.w_emit}")
        if not 0 <= self.roulette_depth <= 64:
            raise ValueError(f"features: roulette_depth: expected 0 (off) ..64, got {self.roulette_depth}")

    @classmethod
    def everything(cls, max_bounces: int = 10) -> Features:
        return cls(one_sided=True, max_bounces=max_bounces)

    @classmethod
    def only(cls, max_bounces: int = 0, **effects: bool) -> Features:
        """Every effect off but those named: a probe that needs primary hits, or a bare path."""
        off = {f.name: False for f in fields(cls) if f.type in (bool, "bool")}
        return cls(**(off | effects), max_bounces=max_bounces)

    def with_bounces(self, max_bounces: int) -> Features:
        """The same features for another path length; Russian roulette stays only where paths
        are longer than its start (as render/analysis.py decides it)."""
        depth = self.roulette_depth if max_bounces > self.roulette_depth else 0
        return replace(self, max_bounces=max_bounces, roulette_depth=depth)

    def defines(self) -> tuple[str, ...]:
        flags = [
            f"-D FEATURE_{f.name.upper()}" for f in fields(self) if f.type in (bool, "bool") and getattr(self, f.name)
        ]
        roulette = [f"-D ROULETTE_DEPTH={self.roulette_depth}"] if self.roulette_depth else []
        return tuple(flags + [f"-D MAX_BOUNCES={self.max_bounces}"] + roulette)

    def with_overrides(self, overrides: dict | None) -> Features:
        return replace(self, **(overrides or {}))

    def to_json(self) -> dict:
        return {"version": FORMAT_VERSION, "features": asdict(self)}

    @classmethod
    def from_json(cls, data: dict) -> Features:
        return cls(**data["features"])

    @classmethod
    def read(cls, path) -> Features:
        with open(path) as handle:
            return cls.from_json(json.load(handle))


# Effects compiled in, turned off: (switch, kind, flags, applies). kind "bias": the image loses a
# term; "variance": a sampling strategy, unbiased, only the noise changes. Emission is dropped only
# where the sky is left to light the room (else the image is black); the window alone is not,
# since without it no path reaches the sky of these closed rooms (environment off, with less work).
COMPILED_IN_OFF = (
    ("specular off", "bias", {"specular": False}, lambda f: f.specular),
    (
        "environment off (window, env sampling with it)",
        "bias",
        {"environment": False, "window": False, "env_sampling": False},
        lambda f: f.environment,
    ),
    (
        "emission off (emitter sampling with it)",
        "bias",
        {"emission": False, "emitter_sampling": False},
        lambda f: f.emission and f.environment,
    ),
    ("emitter sampling off", "variance", {"emitter_sampling": False}, lambda f: f.emitter_sampling),
    ("env sampling off", "variance", {"env_sampling": False}, lambda f: f.env_sampling),
)

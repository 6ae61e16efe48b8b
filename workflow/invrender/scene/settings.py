"""A training stage's settings: a named preset, a user's overrides on top (each of the preset
value's type), and the hash that ties a checkpoint to the settings it was made with."""

from __future__ import annotations

import hashlib
import json

from .types import SceneError

__all__ = ["resolve_preset", "settings_hash"]


def resolve_preset(presets: dict, preset: str, overrides: dict | None, where: str) -> dict:
    """`presets[preset]` with `overrides` on top; an unknown preset or key, or a value of another
    type than the preset's, is refused naming it."""
    if preset not in presets:
        raise SceneError(where, "preset", f"one of {', '.join(presets)}, got {preset!r}")
    settings = dict(presets[preset])
    for key, value in (overrides or {}).items():
        if key not in settings:
            raise SceneError(where, f"overrides.{key}", f"one of the settings {', '.join(sorted(settings))}")
        settings[key] = _typed(settings[key], value, where, key)
    return settings


def _typed(default, value, where: str, key: str):
    """`value` if it has the preset value's type (an int where a float is wanted is a float)."""
    is_number = isinstance(value, (int, float)) and not isinstance(value, bool)
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, float):
        ok, value = is_number, float(value) if is_number else value
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    else:
        ok = isinstance(value, type(default))
    if not ok:
        raise SceneError(
            where, f"overrides.{key}", f"a {type(default).__name__} like the preset's {default!r}, got {value!r}"
        )
    return value


def settings_hash(settings: dict, not_hashed=()) -> str:
    """What a checkpoint must agree with to resume: every setting that changes the computation
    (all but `not_hashed`)."""
    kept = {key: value for key, value in settings.items() if key not in set(not_hashed)}
    return hashlib.sha256(json.dumps(kept, sort_keys=True).encode()).hexdigest()[:16]

"""The `features` stage: analyse a scene directory, write features.json with the evidence."""

from __future__ import annotations

import json
import logging
from pathlib import Path

from ..render.analysis import AnalysisSettings, analyse_scene, warn_unphysical_albedo
from ..scene.atomic import atomic_path, check_output
from ..scene.format import load_scene
from ..scene.types import SceneError

log = logging.getLogger(__name__)


def is_features_json(path: Path) -> bool:
    """An earlier features.json (a JSON object with the evidence), which --out may replace."""
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(document, dict) and "evidence" in document


def run(
    scene_dir,
    out_path,
    settings: AnalysisSettings = AnalysisSettings(),
    overrides: dict | None = None,
    device: str | None = None,
):
    """Analyse a scene directory and write features.json (features + the evidence behind them)."""
    check_output(out_path, "features", is_features_json)  # before the work, not after it
    check_settings(settings)
    scene = load_scene(scene_dir)
    warn_unphysical_albedo(scene.maps, scene_dir, log)
    try:
        features, evidence = analyse_scene(scene, settings, overrides, device)
    except SceneError:  # a SceneError is a ValueError: bad input named by whoever found it
        raise
    except (TypeError, ValueError) as error:  # an unknown --set name, or a combination the kernels refuse
        if not overrides:
            raise
        raise SceneError("features --set", json.dumps(overrides), f"features the kernels allow ({error})") from None
    log.info("features of %s: %s", scene_dir, features)
    document = features.to_json() | {"evidence": evidence}
    with atomic_path(Path(out_path), kind="features", recognise=is_features_json) as tmp:
        Path(tmp).write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    return features


def check_settings(settings: AnalysisSettings) -> None:
    """The analysis settings (config `analysis:` and the flags) within what they mean: bounce
    counts 0..64 (the kernels' limit) with min <= max, a power fraction in (0, 1), a threshold >= 0."""
    where = "features --config analysis / flags"
    for name in ("min_bounces", "max_bounces"):
        value = getattr(settings, name)
        if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= 64:
            raise SceneError(where, name, f"an integer in 0..64, got {value!r}")
    if settings.min_bounces > settings.max_bounces:
        raise SceneError(
            where, "min_bounces", f"at most max_bounces ({settings.max_bounces}), got {settings.min_bounces}"
        )
    if not 0 < settings.bounce_fraction < 1:
        raise SceneError(where, "bounce_fraction", f"a fraction in (0, 1), got {settings.bounce_fraction!r}")
    if not settings.specular_threshold >= 0 or settings.specular_threshold == float("inf"):
        raise SceneError(where, "specular_threshold", f"a finite number >= 0, got {settings.specular_threshold!r}")

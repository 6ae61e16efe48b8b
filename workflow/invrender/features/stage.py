"""The `features` stage: analyse a scene directory, write features.json with the evidence."""

from __future__ import annotations

import json
import logging
from pathlib import Path

from ..render.analysis import AnalysisSettings, analyse_scene, warn_unphysical_albedo
from ..scene.atomic import atomic_path, check_output
from ..scene.format import load_scene

log = logging.getLogger(__name__)


def is_features_json(path: Path) -> bool:
    """An earlier features.json (a JSON object with the evidence), which --out may replace."""
    try:
        document = json.loads(Path(path).read_text(encoding="utf-8"))
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(document, dict) and "evidence" in document


def run(scene_dir, out_path, settings: AnalysisSettings = AnalysisSettings(), overrides: dict | None = None,
        device: str | None = None):
    """Analyse a scene directory and write features.json (features + the evidence behind them)."""
    check_output(out_path, "features", is_features_json)  # before the work, not after it
    scene = load_scene(scene_dir)
    warn_unphysical_albedo(scene.maps, scene_dir, log)
    features, evidence = analyse_scene(scene, settings, overrides, device)
    log.info("features of %s: %s", scene_dir, features)
    document = features.to_json() | {"evidence": evidence}
    with atomic_path(Path(out_path), kind="features", recognise=is_features_json) as tmp:
        Path(tmp).write_text(json.dumps(document, indent=2, allow_nan=False) + "\n")
    return features

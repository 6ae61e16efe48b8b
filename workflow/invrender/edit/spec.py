"""The edit list: read (YAML or JSON), checked against workflow/schemas/edits.schema.yaml, and the
checks a schema cannot make (unique names, mesh files that exist), each failure one SceneError
naming the file and the field, e.g. ``edits.yaml: edits[2].radius: expected this required field``."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import numpy as np
import yaml

from ..scene.cameras import check_camera, pinhole_camera
from ..scene.format import _schema_error
from ..scene.types import Camera, SceneError

SCHEMA_PATH = Path(__file__).resolve().parents[2] / "schemas" / "edits.schema.yaml"
KINDS = ("relight", "insert", "material", "camera")
VIEW_KEYS = ("eye", "target", "fov_deg", "width", "height")


@functools.lru_cache(maxsize=1)
def _validator():
    import jsonschema

    schema = yaml.safe_load(SCHEMA_PATH.read_text(encoding="utf-8"))
    cls = jsonschema.validators.validator_for(schema)
    cls.check_schema(schema)
    return cls(schema)


def read_edits(path) -> list[dict]:
    """An edit list from a YAML or JSON file (JSON is YAML): the list itself, or a mapping whose
    `edits` key holds it (a config file)."""
    path = Path(path)
    try:
        doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise SceneError(path, "(file)", "an existing YAML or JSON file of edits") from None
    except (OSError, UnicodeDecodeError) as error:
        raise SceneError(path, "(file)", f"a readable UTF-8 file ({error})") from None
    except yaml.YAMLError as error:
        raise SceneError(path, "(document)", f"valid YAML or JSON ({' '.join(str(error).split())})") from None
    if isinstance(doc, dict) and "edits" in doc:
        doc = doc["edits"]
    return doc


def _message(error) -> str | None:
    """Words for the combinators whose jsonschema messages print the whole document."""
    if error.validator == "anyOf" and all(set(s) == {"required"} for s in error.validator_value):
        return "one of the fields " + ", ".join(s["required"][0] for s in error.validator_value)
    if error.validator == "not" and set(error.validator_value) == {"required"}:
        return "only one of the fields " + " and ".join(error.validator_value["required"])
    if error.validator == "anyOf" and "description" in error.schema:
        return error.schema["description"].rstrip(".").lower() + f", got {json.dumps(error.instance)}"
    return None


def check_edits(edits, source="edits") -> list[dict]:
    """The list, validated (schema, then unique names and existing mesh files); `source` is the
    file the list came from (or "config"), named in every error. Returns it unchanged."""
    from jsonschema.exceptions import best_match

    error = best_match(_validator().iter_errors(edits))
    if error is not None:
        found = _schema_error(Path(str(source)), error)
        field = "edits" + (found.field if found.field.startswith("[") else f".{found.field}")
        if found.field == "(document)":
            field = "edits"
        raise SceneError(source, field, _message(error) or found.expected)
    seen = set()
    for k, edit in enumerate(edits):
        if edit["name"] in seen:
            raise SceneError(source, f"edits[{k}].name", f"a name no other edit has, got {edit['name']!r} twice")
        seen.add(edit["name"])
        if "mesh" in edit and not Path(edit["mesh"]).is_file():
            raise SceneError(
                source, f"edits[{k}].mesh", f"an existing mesh file: {Path(edit['mesh']).resolve()} does not exist"
            )
        box = edit.get("box")
        if box and not np.all(np.asarray(box["min"]) <= np.asarray(box["max"])):
            raise SceneError(source, f"edits[{k}].box", f"min <= max on every axis, got {box['min']} and {box['max']}")
        view = edit_view(edit, source, k)
        if view is not None:
            check_camera(view, source, f"edits[{k}]")
    return edits


def edit_view(edit: dict, source="edits", index: int = 0) -> Camera | None:
    """The edit's own camera (kind `camera`: its top-level keys; others: an optional `camera`),
    named "camera"; None when the scene's cameras are rendered."""
    view = edit if edit["kind"] == "camera" else edit.get("camera")
    if view is None:
        return None
    eye, target = np.asarray(view["eye"], np.float64), np.asarray(view["target"], np.float64)
    where = f"edits[{index}]" + ("" if edit["kind"] == "camera" else ".camera")
    up = np.array([0.0, 1.0, 0.0])
    direction = target - eye
    if not np.linalg.norm(np.cross(direction, up)) > 1e-9 * max(np.linalg.norm(direction), 1e-300):
        raise SceneError(source, f"{where}.target", "a target not straight above or below the eye (+Y is up)")
    return pinhole_camera("camera", eye, target, view["width"], view["height"], view["fov_deg"])

"""Configuration checks and the input functions every rule shares.

The config is validated against workflow/schemas/config.schema.yaml (defaults filled in), then
each scene's mode is settled and checked against the file system: a capture that lacks what its
mode needs, or names a file that is not there, stops the workflow here, before any job runs,
with one message naming the scene, the key and the path. So do what the schema cannot say (a
generator override of the wrong type, min_bounces above max_bounces, contradictory feature
overrides) and an OpenCL device that is not there: a job that fails on its config has had its
previous outputs deleted already.
"""

import json
import os
import re
import reprlib
import shlex
import shutil
import sys
from pathlib import Path

import jsonschema
import yaml

from snakemake.exceptions import WorkflowError
from snakemake.logging import logger
from snakemake.utils import validate

SCHEMA = "../schemas/config.schema.yaml"

_SCALARS = {
    "integer": lambda v: isinstance(v, int) and not isinstance(v, bool),
    "number": lambda v: isinstance(v, (int, float)) and not isinstance(v, bool),
    "boolean": lambda v: isinstance(v, bool),
    "null": lambda v: v is None,
}


def coerce_strings(value, schema):
    """`--config geometry="{target_faces: 1000}"` hands nested values over as strings (snakemake
    reads them with YAML's BaseLoader): read a string as YAML where the schema wants a number,
    a boolean or null, so that such overrides work. Anything else is left to the validation.
    """
    if isinstance(value, dict):
        properties = schema.get("properties", {})
        extra = schema.get("additionalProperties")
        for key, item in value.items():
            subschema = properties.get(key, extra if isinstance(extra, dict) else None)
            if subschema:
                value[key] = coerce_strings(item, subschema)
        return value
    if isinstance(value, list) and isinstance(schema.get("items"), dict):
        return [coerce_strings(item, schema["items"]) for item in value]
    types = schema.get("type", [])
    types = [types] if isinstance(types, str) else types
    if isinstance(value, str) and any(t in _SCALARS for t in types):
        try:
            parsed = yaml.safe_load(value)
        except yaml.YAMLError:
            return value
        if any(_SCALARS[t](parsed) for t in types if t in _SCALARS):
            return parsed
    return value


# ---------------------------------------------------------------------------- schema errors

# A value quoted in a message: its start. (Repr's keywords need Python 3.12.)
_SHORT = reprlib.Repr()
_SHORT.maxstring = _SHORT.maxother = 40
_SHORT.maxdict = _SHORT.maxlist = 4
_SHORT.maxlevel = 2


def _schema_problem(error):
    """(key below the error's path or None, what is wrong and what is allowed) of a
    jsonschema error, in a few words: never the schema itself, which jsonschema prints whole.
    """
    value, instance, schema = error.validator_value, error.instance, error.schema
    if error.validator == "additionalProperties":
        allowed = list(schema.get("properties", {}))
        extra = [key for key in instance if key not in allowed]
        listing = f"allowed: {', '.join(allowed)}"
        if len(extra) == 1:
            return extra[0], f"unknown key; {listing}"
        return None, f"unknown keys {', '.join(map(str, extra))}; {listing}"
    if error.validator == "required":
        missing = [key for key in value if key not in instance]
        return missing[0], "required, but not given"
    if error.validator == "enum":
        allowed = ", ".join(map(str, value))
        return None, f"{instance!r} is not allowed; allowed: {allowed}"
    if error.validator == "oneOf" and all(list(b) == ["required"] for b in value):
        keys = [key for branch in value for key in branch["required"]]
        present = [key for key in keys if key in instance] or ["neither"]
        return None, f"give one of {' or '.join(keys)} (got {' and '.join(present)})"
    if error.validator == "type":
        types = [value] if isinstance(value, str) else value
        expected = " or ".join(map(repr, types))
        return None, f"{_SHORT.repr(instance)} is not of type {expected}"
    message = error.message
    if len(message) > 160 or "\n" in message:
        message = (
            f"{_SHORT.repr(instance)} fails {error.validator}: {_SHORT.repr(value)}"
        )
    return None, message


def schema_message(error, where=()):
    """One line for a jsonschema error: 'config: <key path>: <what is wrong>; allowed: ...'."""
    key, problem = _schema_problem(error)
    path = [*where, *map(str, error.absolute_path), *([key] if key else [])]
    return f"config: {'.'.join(path) or '(top level)'}: {problem}"


def validate_config():
    """snakemake's validate (it fills in the defaults), its error as one line. Its own message
    carries the failing subschema whole, some 50 lines for a typo; the jsonschema error it
    wraps is the WorkflowError's __context__."""
    try:
        validate(config, schema=SCHEMA)
    except WorkflowError as error:
        cause = error.__context__
        if not isinstance(cause, jsonschema.ValidationError):
            raise
        raise WorkflowError(schema_message(cause)) from None


with open(workflow.source_path(SCHEMA)) as _schema:
    CONFIG_SCHEMA = yaml.safe_load(_schema)
coerce_strings(config, CONFIG_SCHEMA)
validate_config()

# `.venv/bin/snakemake` run without activating the venv: the jobs' `invrender` is the one
# installed beside this snakemake. (PATH is set here, not read, so it needs no `envvars:`.)
_bin = os.path.dirname(sys.executable)
if shutil.which("invrender") is None and os.path.exists(
    os.path.join(_bin, "invrender")
):
    os.environ.update(PATH=_bin + os.pathsep + os.environ.get("PATH", ""))
# envs/*.yaml install the package from here (`-e ${INVRENDER_SOURCE}`) with --sdm conda.
os.environ.setdefault("INVRENDER_SOURCE", workflow.basedir)

SCENES = config["scenes"]
_SCENE_SCHEMA = CONFIG_SCHEMA["properties"]["scenes"]["additionalProperties"]
# Which modes take each capture key (the schema's `x-modes`), and what each mode builds once its
# stages land (`x-stages`): the schema says both, for the docs and for the messages here.
CAPTURE_KEYS = _SCENE_SCHEMA["properties"]["capture"]["properties"]
MODE_STAGES = _SCENE_SCHEMA["properties"]["mode"]["x-stages"]
# The capture each generator kind makes (room_photo: one photograph with depth, segmentation and
# field of view, workflow/invrender/scene/room_photo.py's layout).
KIND_MODE = {"room": "multiview", "duplicates": "duplicates", "room_photo": "room"}
# Image files a capture's images/ may hold, the preferred first: an EXR before its PNG preview.
IMAGE_SUFFIXES = (".exr", ".png", ".jpg", ".jpeg", ".tif", ".tiff")
# The photograph of a duplicates or room capture at the capture's top, found without a key naming
# it (scene/room_photo.py's PHOTO_NAMES, the room stages' reader): the first present is the one.
PHOTO_NAMES = ("photo.exr", "photo.png", "photo.jpg", "photo.jpeg")
MESH_NAMES = ("mesh.ply", "mesh.obj")


def is_synthetic(scene):
    return "synthetic" in SCENES[scene]


def mode(scene):
    return SCENES[scene]["mode"]


SYNTHETIC = [name for name in SCENES if is_synthetic(name)]
CAPTURES = [name for name in SCENES if not is_synthetic(name)]


def scenes_pattern(names):
    """A wildcard constraint matching exactly these scenes (none: a pattern nothing matches), so
    that two rules writing results/{scene}/scene/ (bake for multiview scenes, bake_duplicates
    for duplicates scenes) never compete for one scene."""
    return "|".join(re.escape(name) for name in names) or "(?!)"


wildcard_constraints:
    scene="|".join(re.escape(name) for name in SCENES),


# ---------------------------------------------------------------------------- checks


def _refuse(name, key, message):
    raise WorkflowError(f"config: scene {name!r}: scenes.{name}.{key}: {message}")


def _settle_mode(name):
    """Write the scene's mode into its config: a synthetic scene's follows its generator kind
    (set, it must agree), a capture's defaults to multiview."""
    scene = SCENES[name]
    if not is_synthetic(name):
        scene.setdefault("mode", "multiview")
        return
    kind = scene["synthetic"]["kind"]
    made = KIND_MODE[kind]
    if scene.setdefault("mode", made) != made:
        _refuse(
            name,
            "mode",
            f"{scene['mode']!r} disagrees with synthetic.kind {kind!r}, whose capture is "
            f"{made} (leave mode out, or set it to {made!r})",
        )


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def schema_of(default):
    """The JSON schema a generator default implies for its override: the same type (an integer
    where the default is one, any number where it is a float), and a vector's length."""
    if isinstance(default, bool):
        return {"type": "boolean"}
    if isinstance(default, int):
        return {"type": "integer"}
    if isinstance(default, float):
        return {"type": "number"}
    if isinstance(default, str):
        return {"type": "string"}
    if isinstance(default, dict):
        items = {key: schema_of(value) for key, value in default.items()}
        return {"type": "object", "properties": items}
    if isinstance(default, list) and default and all(map(_is_number, default)):
        n = len(default)
        return {
            "type": "array",
            "items": {"type": "number"},
            "minItems": n,
            "maxItems": n,
        }
    if isinstance(default, list):
        return {"type": "array", "items": schema_of(default[0]) if default else {}}
    return {}


def _check_generator_config(name):
    """Overrides of a generator's defaults: an unknown key (the generator's own merge_config
    says which) or a value of another type than the default's is named now, not in a job.
    """
    try:
        from invrender.synthesize import (
            DUPLICATES_DEFAULTS,
            ROOM_DEFAULTS,
            ROOM_PHOTO_DEFAULTS,
        )
        from invrender.synthesize.room import merge_config
    except ImportError:
        # snakemake runs outside the package's environment: the synthesize job checks
        return
    synthetic = SCENES[name]["synthetic"]
    kinds = {
        "room": ROOM_DEFAULTS,
        "duplicates": DUPLICATES_DEFAULTS,
        "room_photo": ROOM_PHOTO_DEFAULTS,
    }
    defaults = kinds[synthetic["kind"]]
    where = f"scenes.{name}.synthetic.config"
    try:
        merge_config(defaults, synthetic["config"], where)
    except ValueError as error:
        raise WorkflowError(f"config: {error}") from None
    schema = schema_of(defaults)
    # --config hands numbers over as strings
    coerce_strings(synthetic["config"], schema)
    errors = jsonschema.Draft202012Validator(schema).iter_errors(synthetic["config"])
    error = jsonschema.exceptions.best_match(errors)
    if error is not None:
        raise WorkflowError(schema_message(error, where.split(".")))


def _check_features():
    """What the schema cannot say of `features`: the bounds' order, and overrides that
    contradict each other (the renderer's own rule, Features.__post_init__, decides)."""
    features = config["features"]
    if features["min_bounces"] > features["max_bounces"]:
        raise WorkflowError(
            f"config: features.min_bounces: {features['min_bounces']} is more than "
            f"features.max_bounces ({features['max_bounces']}); expected at most it"
        )
    try:
        from invrender.render.features import Features
    except ImportError:
        return  # snakemake runs outside the package's environment: the features job checks
    overrides = features["overrides"]
    try:
        # The dependent effects off, so that only the overrides themselves can disagree: the
        # analysis turns them off where the environment is off.
        Features(window=False, env_sampling=False).with_overrides(overrides)
    except ValueError as error:
        problem = str(error).removeprefix("features: ")
        raise WorkflowError(
            f"config: features.overrides: {problem} (got {json.dumps(overrides)})"
        ) from None


def _check_device():
    """The OpenCL device the ray-tracing jobs will choose (render/device.py's choice, given
    config `device` or $INVRENDER_DEVICE) exists, where those jobs run on this machine. On a
    cluster (--jobs with a remote executor) the login node's devices say nothing of the
    compute nodes': each job checks there."""
    selector = config["device"] or os.environ.get("INVRENDER_DEVICE")
    if not selector and not any(has_mesh(scene) for scene in SCENES):
        return  # nothing traces rays: no device needed
    if not workflow.is_main_process or workflow.resource_settings.nodes is not None:
        if selector:
            logger.info(
                f"config: device {selector!r} not checked here: jobs may run on other "
                "machines (--jobs); each ray-tracing job checks it where it runs"
            )
        return
    try:
        from invrender.render.device import DeviceError, choose_device
    except ImportError as error:
        if selector:
            logger.warning(
                f"config: device {selector!r} not checked: snakemake's Python cannot "
                f"import {error.name} (it runs outside the package's environment); each "
                "ray-tracing job checks it"
            )
        return
    try:
        choose_device(config["device"])
    except DeviceError as error:
        if config["device"]:
            raise WorkflowError(f"config: {error}") from None
        problem = str(error).removeprefix("device: ")
        source = "$INVRENDER_DEVICE (config device is null)" if selector else "device"
        raise WorkflowError(f"config: {source}: {problem}") from None


def cameras_file(capture):
    """Where a capture keeps its cameras: sparse/ (or COLMAP's sparse/0/), else transforms.json;
    None if it has neither."""
    for candidate in ("sparse/0", "sparse"):
        folder = Path(capture, candidate)
        if any(folder.glob("cameras.*")) and any(folder.glob("images.*")):
            return candidate
    if Path(capture, "transforms.json").is_file():
        return "transforms.json"
    return None


def partial_model(capture):
    """A sparse/ (or sparse/0/) that holds half a COLMAP model, cameras without images or
    the reverse, as (the folder, the file it has, the half it lacks); else None."""
    for candidate in ("sparse/0", "sparse"):
        folder = Path(capture, candidate)
        cameras = sorted(folder.glob("cameras.*"))
        images = sorted(folder.glob("images.*"))
        if bool(cameras) != bool(images):
            lacks = "images" if cameras else "cameras"
            return folder, (cameras or images)[0].name, lacks
    return None


def capture_mesh(capture):
    """A capture's mesh or point cloud: the one `mesh` names, else mesh.ply or mesh.obj in it;
    None if there is none."""
    if "mesh" in capture:
        return str(Path(capture["path"], capture["mesh"]))
    for name in MESH_NAMES:
        if Path(capture["path"], name).is_file():
            return str(Path(capture["path"], name))
    return None


def photographs(folder):
    """The images in ``folder``, one per stem (an EXR before its PNG preview), sorted."""
    found = {}
    for path in sorted(Path(folder).iterdir()) if Path(folder).is_dir() else ():
        suffix = path.suffix.lower()
        if suffix not in IMAGE_SUFFIXES or not path.is_file():
            continue
        best = found.get(path.stem)
        if best is None or IMAGE_SUFFIXES.index(suffix) < IMAGE_SUFFIXES.index(
            best.suffix.lower()
        ):
            found[path.stem] = path
    return [found[stem] for stem in sorted(found)]


def _named_file(name, key, suffixes, folder=False):
    """The file (or, with ``folder``, file or folder) that capture key ``key`` ('depth',
    'segmentation.ids') names, relative to the capture directory; refused if it is not there
    or not of one of ``suffixes``."""
    capture = SCENES[name]["capture"]
    value = capture
    for part in key.split("."):
        value = value[part]
    path = Path(capture["path"], value)
    if not (path.is_file() or (folder and path.is_dir())):
        _refuse(
            name,
            f"capture.{key}",
            f"{str(path)!r} does not exist (a relative path is relative to the capture "
            f"directory, scenes.{name}.capture.path)",
        )
    if path.is_file() and path.suffix.lower() not in suffixes:
        _refuse(
            name, f"capture.{key}", f"{str(path)!r}: expected {' or '.join(suffixes)}"
        )
    return path


def _check_multiview(name, capture):
    """A mesh or point cloud, cameras and images."""
    path = capture["path"]
    if "mesh" in capture:
        _named_file(name, "mesh", (".ply", ".obj"))
    elif capture_mesh(capture) is None:
        _refuse(
            name,
            "capture.mesh",
            f"not set, and {path!r} has neither mesh.ply nor mesh.obj: a multiview scene "
            "needs a mesh, or a point cloud with normals (PLY or OBJ)",
        )
    if cameras_file(path) is None:
        _refuse(
            name,
            "capture.path",
            f"{path!r} has no cameras: expected sparse/ (a COLMAP model: cameras and "
            "images, .txt or .bin) or transforms.json",
        )
    if not photographs(Path(path, "images")):
        _refuse(
            name,
            "capture.path",
            f"{str(Path(path, 'images'))!r} holds no images (EXR, PNG or JPEG)",
        )


def find_photograph(capture):
    """The photograph of a duplicates or room capture (its config mapping), where the room
    stages' reader (scene/room_photo.py) looks for it: the file `image` names; else the first of
    PHOTO_NAMES at the capture's top (an EXR before its PNG preview); else the one image of
    images/. None if there is none of these (images/ missing, empty or with several)."""
    path = Path(capture["path"])
    if "image" in capture:
        return path / capture["image"]
    for photo in PHOTO_NAMES:
        if (path / photo).is_file():
            return path / photo
    images = photographs(path / "images")
    return images[0] if len(images) == 1 else None


def _check_photograph(name, capture):
    """One photograph, and its cameras at most one way (a model, or a field of view)."""
    path = capture["path"]
    if "image" in capture:
        _named_file(name, "image", IMAGE_SUFFIXES)
    elif find_photograph(capture) is None:
        images = photographs(Path(path, "images"))
        names = ", ".join(p.name for p in images[:5]) or "none"
        others = ", ".join(p.name for p in photographs(path)[:5])
        top = ", ".join(PHOTO_NAMES[:3])
        _refuse(
            name,
            "capture.image",
            f"not set, and {path!r} has none of {top} at its top"
            f"{f' (it has {others})' if others else ''}, and {str(Path(path, 'images'))!r} "
            f"holds {len(images)} images ({names}), not one: a {mode(name)} scene is one "
            f"photograph; put it at the top as one of {top}, or alone in images/, or name "
            "it with capture.image",
        )
    _check_lens(name, capture)


def _check_lens(name, capture):
    """A field of view or a focal length, not both, and not beside a camera model."""
    path = capture["path"]
    given = [key for key in ("field_of_view", "focal_length") if key in capture]
    if len(given) == 2:
        _refuse(
            name, "capture.focal_length", "give field_of_view or focal_length, not both"
        )
    if given and cameras_file(path) is not None:
        _refuse(
            name,
            f"capture.{given[0]}",
            f"{path!r} has cameras ({cameras_file(path)}) as well: give one of them",
        )


def _check_duplicates(name, capture):
    _check_photograph(name, capture)
    if "masks" in capture:
        masks = _named_file(name, "masks", (".png",), folder=True)
        if masks.is_dir() and not any(masks.glob("*.png")):
            _refuse(name, "capture.masks", f"{str(masks)!r} holds no PNG")


# The room capture's own layout (scene/room_photo.py): files at the top of the capture, found
# without a key naming them (the photograph's are PHOTO_NAMES): the depth map, and the panoptic
# segmentation's id image and its label table (JSON, else CSV).
ROOM_DEPTH = "depth.exr"
ROOM_IDS = "panoptic.png"
ROOM_LABELS = ("panoptic.json", "panoptic.csv")


def _room_segmentation(path):
    """(the id image, the label table) found in a room capture's layout, each None if absent."""
    ids = path / ROOM_IDS
    labels = next((path / f for f in ROOM_LABELS if (path / f).is_file()), None)
    return (ids if ids.is_file() else None), labels


def _room_missing(capture):
    """What a room capture lacks of what the room stages need, as text for people."""
    path = Path(capture["path"])
    missing = []
    if "depth" not in capture and not (path / ROOM_DEPTH).is_file():
        missing.append(
            f"a depth map (capture.depth, or {ROOM_DEPTH} in the capture; EXR, any scale)"
        )
    if "segmentation" not in capture and None in _room_segmentation(path):
        missing.append(
            "a panoptic segmentation (capture.segmentation {ids, labels}, or "
            f"{ROOM_IDS} and {' or '.join(ROOM_LABELS)} in the capture)"
        )
    return missing


def has_room_inputs(scene):
    """A room scene with what room_box needs: a synthetic room photo, or a capture with depth
    and segmentation (without them `all` leaves the stage out; asked for, it says what to
    provide)."""
    if mode(scene) != "room":
        return False
    return is_synthetic(scene) or not _room_missing(SCENES[scene]["capture"])


def _check_room(name, capture):
    """The photograph (photo.exr/png/jpg, or images/ with one, or `image`); depth and a panoptic
    segmentation named or in the capture's layout (half a segmentation there is refused). What
    is missing is said now: the room stages will stop without depth or segmentation (nothing
    here can estimate them), and estimate a field of view not given from vanishing
    points."""
    path = Path(capture["path"])
    _check_photograph(name, capture)
    if "depth" in capture:
        _named_file(name, "depth", (".exr",))
    if "segmentation" in capture:
        _named_file(name, "segmentation.ids", (".png",))
        _named_file(name, "segmentation.labels", (".json", ".csv"))
    else:
        ids, labels = _room_segmentation(path)
        if (ids is None) != (labels is None):
            have = ids or labels
            lack = " or ".join(ROOM_LABELS) if labels is None else ROOM_IDS
            _refuse(
                name,
                "capture.segmentation",
                f"not set, and {str(have)!r} is there without its other half: put {lack} "
                "beside it, or name both with capture.segmentation {ids, labels}",
            )
    missing = _room_missing(capture)
    if missing:
        logger.warning(
            f"config: scene {name!r}: the room capture {str(path)!r} lacks "
            f"{' and '.join(missing)}: the room stages will stop asking for "
            f"{'them' if len(missing) > 1 else 'it'} (no estimator can be downloaded here)"
        )
    given = any(key in capture for key in ("field_of_view", "focal_length"))
    if not (given or cameras_file(path) or (path / "camera.json").is_file()):
        logger.info(
            f"config: scene {name!r}: no field of view (capture.field_of_view, focal_length or "
            "camera.json): the room stages estimate it from vanishing points"
        )


MODE_CHECKS = {
    "multiview": _check_multiview,
    "duplicates": _check_duplicates,
    "room": _check_room,
}


def _check_capture(name):
    capture = SCENES[name]["capture"]
    path = capture["path"]
    if not Path(path).is_dir():
        _refuse(
            name,
            "capture.path",
            f"capture directory {path!r} does not exist "
            f"(relative paths are relative to the working directory {os.getcwd()})",
        )
    for key in capture:
        modes = CAPTURE_KEYS[key].get("x-modes")
        if modes and mode(name) not in modes:
            _refuse(
                name,
                f"capture.{key}",
                f"a {mode(name)} scene takes no {key} (it is for {' and '.join(modes)} "
                f"scenes; scenes.{name}.mode sets the mode)",
            )
    partial = partial_model(path)
    if partial:
        folder, has, lacks = partial
        _refuse(
            name,
            "capture.path",
            f"{str(folder)!r} holds {has} but no {lacks}.txt or {lacks}.bin: a COLMAP model "
            "is both; complete it (or remove the folder, if the capture has no model)",
        )
    MODE_CHECKS[mode(name)](name, capture)


EDITS_SCHEMA = "../schemas/edits.schema.yaml"
with open(workflow.source_path(EDITS_SCHEMA)) as _schema:
    _EDITS_VALIDATOR = jsonschema.Draft202012Validator(yaml.safe_load(_schema))


def _check_edits(name):
    """Each scene's edit list against edits.schema.yaml, when the workflow starts (the edit job
    checks again, with the scene: emitter numbers, boxes, mesh files)."""
    edits = SCENES[name]["edits"]
    error = jsonschema.exceptions.best_match(_EDITS_VALIDATOR.iter_errors(edits))
    if error is not None:
        raise WorkflowError(schema_message(error, ("scenes", name, "edits")))


for _name in SCENES:
    _settle_mode(_name)
    _check_edits(_name)
for _name in SYNTHETIC:
    _check_generator_config(_name)
for _name in CAPTURES:
    _check_capture(_name)
_check_features()


# ---------------------------------------------------------------------------- targets


def lens(scene):
    """A photograph's field_of_view or focal_length key, if its capture gives one instead of
    cameras (the cameras rule then makes its one camera)."""
    capture = SCENES[scene].get("capture", {})
    return next(
        (key for key in ("field_of_view", "focal_length") if key in capture), None
    )


def has_cameras(scene):
    """A COLMAP model or a lens for the cameras rule. A synthetic room photo has neither: its
    field of view is in camera.json, which the room stages read (with the photo)."""
    if is_synthetic(scene):
        return mode(scene) != "room"
    if lens(scene):
        return True
    return cameras_file(SCENES[scene]["capture"]["path"]) is not None


def has_mesh(scene):
    """A multiview scene brings its mesh (a synthetic capture its scan); a duplicates scene's is
    recovered from its photograph (duplicates/object.ply)."""
    return mode(scene) in ("multiview", "duplicates")


_check_device()


def recovers(scene):
    """The modes recovered from cameras: multiview (milo_train, bake) and duplicates (segment,
    duplicates, geometry, bake_duplicates), which also get `accuracy` and `summary`. A room
    scene's stages (room_box to bake_room) hang on its depth and segmentation instead
    (has_room_inputs)."""
    return mode(scene) in ("multiview", "duplicates")


MULTIVIEW = [name for name in SCENES if mode(name) == "multiview"]
DUPLICATES = [name for name in SCENES if mode(name) == "duplicates"]
ROOM = [name for name in SCENES if mode(name) == "room"]


def scene_targets(scene):
    """The targets of `all`: each artifact whose stage exists and whose inputs the scene has."""
    results = f"results/{scene}"
    targets = [f"{results}/capture"] if is_synthetic(scene) else []
    if has_cameras(scene):
        targets.append(f"{results}/cameras")
    if mode(scene) == "multiview":
        targets += [
            f"{results}/geometry",
            f"{results}/gradients",
            f"{results}/milo/weights.pt",
        ]
    if has_room_inputs(scene):
        targets += [
            f"{results}/room_box",
            f"{results}/room_lights",
            f"{results}/room_objects",
        ]
        # the room scene (bake_room) and what runs on any scene directory
        targets += [
            f"{results}/scene",
            f"{results}/features.json",
            f"{results}/renders",
            f"{results}/export",
        ]
        if SCENES[scene]["edits"]:
            targets.append(f"{results}/edits")
        if is_synthetic(scene):
            targets.append(f"{results}/report")
    if mode(scene) == "duplicates" and has_cameras(scene):
        targets += [
            f"{results}/segmentation",
            f"{results}/duplicates",
            f"{results}/geometry",
        ]
    if recovers(scene) and has_cameras(scene):
        targets += [
            f"{results}/scene",
            f"{results}/features.json",
            f"{results}/renders",
            f"{results}/export",
        ]
        if SCENES[scene]["edits"]:
            targets.append(f"{results}/edits")
    if recovers(scene) and is_synthetic(scene):
        targets.append(f"{results}/report")
    if recovers(scene) and has_cameras(scene):
        targets += [f"{results}/accuracy", f"{results}/summary"]
    return targets


def planned(scene):
    """What the scene's mode will build once its stages land, as plain text."""
    text = MODE_STAGES[mode(scene)]["planned"].replace("`", "")
    return text.replace("{scene}", scene)


for _name in CAPTURES:
    logger.info(
        f"scene {_name!r} ({mode(_name)}, a capture of your own): builds "
        f"{', '.join(scene_targets(_name)) or 'nothing yet'}; once its stages land, "
        f"{planned(_name)}"
    )


# ---------------------------------------------------------------------------- input functions


def capture_dir(wildcards):
    """The scene's capture: what the synthesize rule writes, or the user's directory."""
    if is_synthetic(wildcards.scene):
        return f"results/{wildcards.scene}/capture"
    return SCENES[wildcards.scene]["capture"]["path"]


def _lacks(wildcards, what):
    scene = wildcards.scene
    raise WorkflowError(
        f"scene {scene!r} is a {mode(scene)} capture without {what}; once its stages land, "
        f"{planned(scene)}"
    )


def geometry_mesh(wildcards):
    """The mesh that geometry reads (a synthetic capture's mesh.ply, or the user's)."""
    if mode(wildcards.scene) == "duplicates":
        return f"results/{wildcards.scene}/duplicates/object.ply"
    if is_synthetic(wildcards.scene):
        return os.path.join(capture_dir(wildcards), "mesh.ply")
    if not has_mesh(wildcards.scene):
        _lacks(wildcards, "a mesh (the geometry rule's input)")
    return capture_mesh(SCENES[wildcards.scene]["capture"])


def geometry_mesh_input(wildcards):
    if mode(wildcards.scene) == "duplicates":
        return f"results/{wildcards.scene}/duplicates"
    if is_synthetic(wildcards.scene):
        return capture_dir(wildcards)
    return geometry_mesh(wildcards)


def capture_cameras(wildcards):
    """The capture's cameras: a COLMAP model directory or a transforms.json file."""
    if is_synthetic(wildcards.scene):
        return os.path.join(capture_dir(wildcards), "sparse")
    if lens(wildcards.scene):
        return str(photograph(wildcards.scene))
    if not has_cameras(wildcards.scene):
        _lacks(
            wildcards, "cameras (sparse/ or transforms.json, the cameras rule's input)"
        )
    return os.path.join(capture_dir(wildcards), cameras_file(capture_dir(wildcards)))


def photograph(scene):
    """The one photograph of a duplicates or room capture (find_photograph's; the checks have
    refused a capture without one)."""
    return find_photograph(SCENES[scene]["capture"])


def images_folder(wildcards):
    """The folder the capture's cameras name their images relative to (the cameras rule's
    --images): a synthetic or multiview capture's images/; the folder that holds a duplicates or
    room capture's photograph (images/, or the capture itself for a photo.exr there)."""
    scene = wildcards.scene
    if is_synthetic(scene) or mode(scene) == "multiview":
        return os.path.join(capture_dir(wildcards), "images")
    return str(photograph(scene).parent)


def capture_images(wildcards):
    """The cameras rule's images: a synthetic capture is one directory output, so the rule
    depends on that directory; a user's capture on its images/ or its one photograph, so that
    replacing one re-runs the rule."""
    if is_synthetic(wildcards.scene):
        return capture_dir(wildcards)
    if mode(wildcards.scene) == "multiview":
        return images_folder(wildcards)
    return str(photograph(wildcards.scene))


def cameras_options(wildcards):
    """The cameras rule's flags: a photograph's lens, else the images folder the model names."""
    key = lens(wildcards.scene)
    if key:
        value = SCENES[wildcards.scene]["capture"][key]
        return f"--{key.replace('_', '-')} {value}"
    return f"--images {shlex.quote(images_folder(wildcards))}"


def capture_cameras_input(wildcards):
    if is_synthetic(wildcards.scene):
        return capture_dir(wildcards)
    return capture_cameras(wildcards)


# ---------------------------------------------------------------------------- duplicates
# (the input functions of workflow/rules/duplicates.smk)


def segmentation_dir(wildcards):
    """The segment checkpoint's folder (asking for it makes snakemake re-plan once it exists)."""
    return checkpoints.segment.get(scene=wildcards.scene).output[0]


def photograph_stem(scene):
    """The stem of the photograph (its mask is masks/<stem>.png)."""
    if is_synthetic(scene):
        return "view_000"
    return photograph(scene).stem


def instance_masks(wildcards):
    return f"results/{wildcards.scene}/segmentation/masks/{photograph_stem(wildcards.scene)}.png"


def instance_files(suffix):
    """The per-instance files of duplicates_crop (results/{scene}/crops/: a sibling of the solve
    step's folder, which may not contain another rule's outputs)."""

    def function(wildcards):
        return [
            f"results/{wildcards.scene}/crops/instance_{i:03d}{suffix}"
            for i in segmented_instances(wildcards)
        ]

    return function


def duplicates_settings(wildcards):
    """`--set key=value` for each setting: config `duplicates`, then the scene's own."""
    scene = SCENES[wildcards.scene]
    return set_options({**config["duplicates"], **scene.get("duplicates", {})})


# ---------------------------------------------------------------------------- params


def synthesize_config(wildcards):
    """The generator overrides as one line of JSON (JSON is YAML), fed to --config on stdin."""
    return json.dumps(SCENES[wildcards.scene]["synthetic"]["config"], sort_keys=True)


def analysis_options(wildcards):
    """features' analysis settings as flags (--bounce-fraction 0.01 ...)."""
    keys = (
        "bounce_fraction",
        "specular_threshold",
        "max_bounces",
        "min_bounces",
        "roulette_depth",
    )
    return " ".join(
        f"--{key.replace('_', '-')} {config['features'][key]}" for key in keys
    )


def set_options(settings):
    """`--set key=value` for each setting, values as JSON (true, 3, ["a"]): the flag of the
    stages that take overrides (render's features, milo's preset)."""
    return " ".join(
        f"--set {shlex.quote(f'{key}={json.dumps(value)}')}"
        for key, value in sorted(settings.items())
    )


def feature_overrides(wildcards):
    """`--set key=value` for each forced feature."""
    return set_options(config["features"]["overrides"])


def geometry_options(wildcards):
    """Atlas size: a texel density if one is given, else the fixed resolution."""
    geometry = config["geometry"]
    if geometry["texels_per_meter"] is not None:
        size = f"--texels-per-meter {geometry['texels_per_meter']}"
    else:
        size = f"--atlas-resolution {geometry['atlas_resolution']}"
    return (
        f"--target-faces {geometry['target_faces']} {size} "
        f"--padding {geometry['padding']} --poisson-depth {geometry['poisson_depth']} "
        f"--min-island-fraction {geometry['min_island_fraction']} "
        f"--min-island-faces {geometry['min_island_faces']}"
    )


def export_options(wildcards):
    """invrender export's flags: --usdc, --no-instancing. (A duplicates scene is a v2 scene: its
    copies are objects sharing one mesh, which the export instances.)"""
    options = []
    if config["export"]["usdc"]:
        options.append("--usdc")
    if not config["export"]["instancing"]:
        options.append("--no-instancing")
    return " ".join(options)


MILO_RUNTIME = {
    "demo": 30,
    "texels": 30,
    "cpu": 300,
    "paper": 1440,
}  # minutes a job may run (a cluster's --time)


def milo_overrides(scene):
    """The scene's held-out views and each override of the preset."""
    return {"holdout": SCENES[scene]["holdout"], **config["milo"]["overrides"]}


def milo_settings(wildcards):
    """`--set key=value` for the scene's held-out views and each override of the preset."""
    return set_options(milo_overrides(wildcards.scene))


MATERIAL_RUNTIME = {
    "ci": 15,
    "default": 240,
}  # minutes a duplicates_material job may run


def material_overrides(scene):
    """Config `duplicates_material.overrides`, then the scene's own `duplicates_material`."""
    return {
        **config["duplicates_material"]["overrides"],
        **SCENES[scene].get("duplicates_material", {}),
    }


def material_settings(wildcards):
    """`--set key=value` for each override: config `duplicates_material.overrides`, then the
    scene's own `duplicates_material` mapping."""
    return set_options(material_overrides(wildcards.scene))


def material_runtime(wildcards):
    return MATERIAL_RUNTIME[config["duplicates_material"]["preset"]]


def milo_runtime(wildcards):
    return MILO_RUNTIME[config["milo"]["preset"]]


def holdout_options(wildcards):
    return " ".join(
        f"--holdout {shlex.quote(name)}" for name in SCENES[wildcards.scene]["holdout"]
    )


def edit_truth(wildcards):
    """The edit rule's truth: a synthetic scene's capture (its ground_truth/scene), else none."""
    return capture_dir(wildcards) if is_synthetic(wildcards.scene) else []


def edit_truth_option(wildcards):
    if not is_synthetic(wildcards.scene):
        return ""
    # a room photo's truth scene is truth/scene (scene/room_photo.py's layout)
    truth = "truth" if mode(wildcards.scene) == "room" else "ground_truth"
    return (
        f"--truth {shlex.quote(os.path.join(capture_dir(wildcards), truth, 'scene'))}"
    )


def device_option(wildcards):
    device = config["device"]
    return f"--device {shlex.quote(device)}" if device else ""


# ---------------------------------------------------------------------------- accuracy
# (the input functions of workflow/rules/accuracy.smk)

ACCURACY_RUNTIME = {
    "quick": 20,
    "full": 240,
}  # minutes a job may run (a cluster's --time)


def accuracy_inputs(wildcards):
    """A multiview scene's captured images (the gradient sweep's loss) and its training run
    (log.csv, training.json; a synthetic scene's scored snapshots from evaluate); a duplicates
    scene's material run (its log.csv, the same columns: accuracy/recovery.py).
    """
    scene = wildcards.scene
    if mode(scene) == "duplicates":
        material = f"results/{scene}/material"
        inputs = {
            "training": f"{material}/training.json",
            "log_csv": f"{material}/log.csv",
            "runs": recovery_run_dirs(wildcards),
        }
        if is_synthetic(scene):
            inputs["evaluation"] = f"results/{scene}/report"
        return inputs
    if mode(scene) != "multiview":
        return {}
    inputs = {
        "cameras": f"results/{scene}/cameras",
        "training": f"results/{scene}/milo/training.json",
        "log_csv": f"results/{scene}/milo/log.csv",
    }
    if is_synthetic(scene):
        inputs["evaluation"] = f"results/{scene}/report"
    inputs["runs"] = recovery_run_dirs(wildcards)
    return inputs


# The recovery sweep (the recovery_run rule), each configuration of the scene's recovery stage a
# job of its own, named by what it changes, e.g. milo-rays8192, milo-layers2-width32.
RECOVERY_SOURCE = {"multiview": "milo", "duplicates": "duplicates_material"}


def configured_training(source, scene):
    """(preset, overrides) of the scene's recovery stage as configured."""
    if source == "milo":
        return config["milo"]["preset"], milo_overrides(scene)
    return config["duplicates_material"]["preset"], material_overrides(scene)


def run_label(source, change):
    """A run's name from what it changes: letters, digits and dashes (a wildcard, a folder)."""
    parts = [f"{key}{value}" for key, value in change.items()]
    return re.sub(r"[^A-Za-z0-9.-]+", "", "-".join([source.replace("_", "-"), *parts]))


def recovery_runs(scene):
    """{label: {"source", "preset", "overrides"}} of the scene's recovery sweep (config
    accuracy.recovery for the budget): the stage's configured preset and overrides, then the
    budget's base, then the run's own. Only synthetic scenes: a run is scored by the truth.
    """
    source = RECOVERY_SOURCE.get(mode(scene))
    if source is None or not is_synthetic(scene) or not has_cameras(scene):
        return {}
    budget = config["accuracy"]["budget"]
    where = f"config: accuracy.recovery.{budget}.{source}"
    sweep = config["accuracy"]["recovery"][budget].get(source)
    if not isinstance(sweep, dict) or not isinstance(sweep.get("runs"), list):
        raise WorkflowError(
            f"{where}: expected {{base: {{...}}, runs: [{{...}}, ...]}}, got {sweep!r}"
        )
    preset, overrides = configured_training(source, scene)
    runs = {}
    for change in sweep["runs"]:
        if not isinstance(change, dict):
            raise WorkflowError(
                f"{where}.runs: expected mappings of settings, got {change!r}"
            )
        label = run_label(source, change)
        if label in runs:
            raise WorkflowError(f"{where}.runs: {change!r} is there twice")
        own = {key: value for key, value in change.items() if key != "preset"}
        runs[label] = {
            "source": source,
            "preset": change.get("preset", preset),
            "overrides": {**overrides, **sweep.get("base", {}), **own},
        }
    return runs


def recovery_run_dirs(wildcards):
    return [
        f"results/{wildcards.scene}/accuracy_runs/{label}"
        for label in recovery_runs(wildcards.scene)
    ]


def recovery_run(wildcards):
    runs = recovery_runs(wildcards.scene)
    if wildcards.run not in runs:
        raise WorkflowError(
            f"results/{wildcards.scene}/accuracy_runs/{wildcards.run}: not a run of the scene's "
            f"recovery sweep ({', '.join(runs) or 'none'})"
        )
    return runs[wildcards.run]


def recovery_run_inputs(wildcards):
    """What the run's stage reads, and the truth that scores it."""
    scene = wildcards.scene
    inputs = {
        "geometry": f"results/{scene}/geometry",
        "cameras": f"results/{scene}/cameras",
        "capture": f"results/{scene}/capture",
    }
    if recovery_run(wildcards)["source"] == "duplicates_material":
        inputs["duplicates"] = f"results/{scene}/duplicates"
        inputs["segmentation"] = segmentation_dir(wildcards)
    return inputs


def recovery_run_options(wildcards):
    """accuracy-run's --source, --preset, --set and --input flags."""
    run, scene = recovery_run(wildcards), wildcards.scene
    inputs = {
        "geometry": f"results/{scene}/geometry",
        "cameras": f"results/{scene}/cameras",
    }
    if run["source"] == "milo":
        inputs |= {
            "images": f"results/{scene}/cameras/images",
            "truth": f"results/{scene}/capture/ground_truth/scene",
        }
    else:
        inputs |= {
            "duplicates": f"results/{scene}/duplicates",
            "masks": instance_masks(wildcards),
            "segmentation": f"results/{scene}/segmentation",
            "truth": f"results/{scene}/capture/ground_truth",
            "images": f"results/{scene}/capture/images",
        }
    flags = [
        f"--source {run['source']}",
        f"--preset {shlex.quote(run['preset'])}",
        set_options(run["overrides"]),
    ]
    flags += [
        f"--input {shlex.quote(f'{name}={path}')}" for name, path in inputs.items()
    ]
    return " ".join(flags)


def accuracy_options(wildcards):
    scene = wildcards.scene
    options = []
    if mode(scene) == "multiview":
        options += [
            f"--images results/{scene}/cameras/images",
            f"--milo results/{scene}/milo",
        ]
    if mode(scene) == "duplicates":
        options.append(f"--run duplicates_material=results/{scene}/material")
    if is_synthetic(
        scene
    ):  # the configured run's scores (evaluate's), and the sweep's runs
        options.append(f"--metrics results/{scene}/report/metrics.json")
    options += [f"--sweep {path}" for path in recovery_run_dirs(wildcards)]
    camera = config["accuracy"]["camera"]
    if camera:
        options.append(f"--camera {shlex.quote(camera)}")
    return " ".join(options)


def recovery_score_spp(wildcards):
    return config["accuracy"]["recovery"][config["accuracy"]["budget"]]["score_spp"]


def accuracy_runtime(wildcards):
    return ACCURACY_RUNTIME[config["accuracy"]["budget"]]


def summary_inputs(wildcards):
    """Everything the scene builds (the summary reads their benchmark records and metrics)."""
    summary = f"results/{wildcards.scene}/summary"
    return [t for t in scene_targets(wildcards.scene) if t != summary]


# ---------------------------------------------------------------------------- resources

# Words of a CPU device's "platform / device" (render/device.py's names): PoCL's, and Intel's CPU
# runtime, whose platform is "Intel(R) OpenCL" (its GPUs' "Intel(R) OpenCL Graphics").
CPU_DEVICE_WORDS = (
    "pocl",
    "portable computing",
    "pthread",
    "cpu",
    "intel(r) opencl /",
    "xeon",
    "epyc",
    "ryzen",
    "processor",
)


def gpu_request(wildcards):
    """GPUs a ray-tracing job asks for (resource `gpu`, which snakemake-executor-plugin-slurm
    turns into --gpus=N): one when config["device"] names a device that is not a CPU one. With
    device null the job uses whatever the node has, so it asks for none."""
    device = (config["device"] or "").lower()
    if not device or any(word in device for word in CPU_DEVICE_WORDS):
        return 0
    return 1


# ---------------------------------------------------------------------------- room
# (the input functions of workflow/rules/room_box.smk)


def room_box_capture_files(wildcards):
    """The capture's files the stage reads where the config names them (relative to the
    capture), as --photo/--depth/--ids/--labels values."""
    if is_synthetic(wildcards.scene):
        return {}
    capture = SCENES[wildcards.scene]["capture"]
    files = {"photo": capture.get("image"), "depth": capture.get("depth")}
    files |= {
        key: capture.get("segmentation", {}).get(key) for key in ("ids", "labels")
    }
    return {key: value for key, value in files.items() if value is not None}


def room_box_input(wildcards):
    """A synthetic capture is one directory output; a user's capture the directory and the
    files the config names, so that editing one re-runs the stage."""
    files = [capture_dir(wildcards)]
    if not is_synthetic(wildcards.scene):
        files += [
            os.path.join(capture_dir(wildcards), value)
            for value in room_box_capture_files(wildcards).values()
        ]
    return files


def room_box_options(wildcards):
    """Flags: the named files and the lens (`capture.field_of_view` is horizontal)."""
    options = [
        f"--{key} {shlex.quote(value)}"
        for key, value in room_box_capture_files(wildcards).items()
    ]
    if not is_synthetic(wildcards.scene):
        capture = SCENES[wildcards.scene]["capture"]
        if "field_of_view" in capture:
            options.append(f"--fov-x {capture['field_of_view']}")
        elif "focal_length" in capture:
            options.append(f"--focal-length {capture['focal_length']}")
    return " ".join(options)


def room_lights_options(wildcards):
    """The capture's photo and segmentation files where the config names them (room_box's)."""
    return " ".join(
        f"--{key} {shlex.quote(value)}"
        for key, value in room_box_capture_files(wildcards).items()
        if key != "depth"
    )


# ---------------------------------------------------------------------------- room scene
# (the input functions of bake_room in workflow/rules/bake.smk and evaluate_room)

# The room stages after room_box whose outputs the room scene takes (bake_room's flags). A user
# stops after the room or the objects by asking for results/{scene}/room_box or room_objects.
ROOM_SCENE_STAGES = {
    "room_lights": "lights",
    "room_objects": "objects",
    "room_materials": "materials",
}


def room_scene_inputs(wildcards):
    results = f"results/{wildcards.scene}"
    inputs = {"room": f"{results}/room_box", "capture": room_box_input(wildcards)}
    for stage, flag in ROOM_SCENE_STAGES.items():
        inputs[flag] = f"{results}/{stage}"
    return inputs


def bake_room_options(wildcards):
    """--lights/--objects/--materials for the stages present, the capture and its named files,
    and the texel density."""
    results = f"results/{wildcards.scene}"
    options = [
        f"--{flag} {results}/{stage}" for stage, flag in ROOM_SCENE_STAGES.items()
    ]
    options.append(f"--capture {shlex.quote(capture_dir(wildcards))}")
    options.append(room_lights_options(wildcards))
    options.append(f"--texels-per-meter {config['bake_room']['texels_per_meter']}")
    return " ".join(option for option in options if option)


def room_evaluate_inputs(wildcards):
    """The room scene, the synthetic capture (its truth/), room_box and the stages present."""
    results = f"results/{wildcards.scene}"
    inputs = {
        "scene": f"{results}/scene",
        "capture": f"{results}/capture",
        "room": f"{results}/room_box",
    }
    for stage, flag in ROOM_SCENE_STAGES.items():
        if stage != "room_materials":
            inputs[flag] = f"{results}/{stage}"
    return inputs


def room_evaluate_options(wildcards):
    """--lights and --objects for the stages present (their fit and metrics)."""
    results = f"results/{wildcards.scene}"
    return " ".join(
        f"--{flag} {results}/{stage}"
        for stage, flag in ROOM_SCENE_STAGES.items()
        if stage != "room_materials"
    )


def room_objects_options(wildcards):
    """The capture's named files (room_box's) and the config's room_objects settings as flags."""
    settings = config["room_objects"]
    options = [
        f"--{key} {shlex.quote(value)}"
        for key, value in room_box_capture_files(wildcards).items()
    ]
    for key in ("iterations", "spp", "candidates", "max_width", "seed"):
        options.append(f"--{key.replace('_', '-')} {settings[key]}")
    options += [f"--asset-dir {shlex.quote(d)}" for d in settings["asset_dirs"]]
    return " ".join(options)


# ---------------------------------------------------------------------------- room materials
# (the input functions of workflow/rules/room_materials.smk)


def room_materials_inputs(wildcards):
    results = f"results/{wildcards.scene}"
    inputs = {
        "capture": room_box_input(wildcards),
        "room": f"{results}/room_box",
        "lights": f"{results}/room_lights",
        "objects": f"{results}/room_objects",
    }
    return inputs


def room_materials_options(wildcards):
    """--objects, the capture's named files, the config's settings,
    and the scene's user crop pairs (as JSON text)."""
    results = f"results/{wildcards.scene}"
    settings = config.get("room_materials", {})
    options = [room_lights_options(wildcards)]
    options.append(f"--objects {results}/room_objects")
    options += [
        f"--rounds {settings.get('rounds', 4)}",
        f"--steps {settings.get('steps', 8)}",
        f"--spp {settings.get('spp', 8)}",
        f"--light-colour {settings.get('light_colour', 'grey')}",
        f"--eval-width {settings.get('eval_width', 256)}",
    ]
    if not settings.get("retrieval", True):
        options.append("--no-retrieval")
    crops = SCENES[wildcards.scene].get("room_materials", {}).get("crops", [])
    if crops:
        options.append(f"--crops {shlex.quote(json.dumps(crops))}")
    return " ".join(option for option in options if option)

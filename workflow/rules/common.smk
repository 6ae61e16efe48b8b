"""Configuration checks and the input functions every rule shares.

The config is validated against workflow/schemas/config.schema.yaml (defaults filled in), then
checked against the file system: a capture that is not there stops the workflow here, before
any job runs, with one message naming the scene, the key and the path.
"""

import json
import os
import re
import shlex
import shutil
import sys
from pathlib import Path

import yaml

from snakemake.exceptions import WorkflowError
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


with open(workflow.source_path(SCHEMA)) as _schema:
    coerce_strings(config, yaml.safe_load(_schema))
validate(config, schema=SCHEMA)

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


def is_synthetic(scene):
    return "synthetic" in SCENES[scene]


SYNTHETIC = [name for name in SCENES if is_synthetic(name)]
CAPTURES = [name for name in SCENES if not is_synthetic(name)]


wildcard_constraints:
    scene="|".join(re.escape(name) for name in SCENES),


# ---------------------------------------------------------------------------- checks


def _check_generator_config(name):
    """Overrides of a generator's defaults: an unknown key is named now, not in a job."""
    try:
        from invrender.synthesize import DUPLICATES_DEFAULTS, ROOM_DEFAULTS
        from invrender.synthesize.room import merge_config
    except ImportError:
        # snakemake runs outside the package's environment: the synthesize job checks
        return
    synthetic = SCENES[name]["synthetic"]
    kinds = {"room": ROOM_DEFAULTS, "duplicates": DUPLICATES_DEFAULTS}
    defaults = kinds[synthetic["kind"]]
    try:
        merge_config(defaults, synthetic["config"], f"scenes.{name}.synthetic.config")
    except ValueError as error:
        raise WorkflowError(f"config: {error}") from None


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


def _check_capture(name):
    path = SCENES[name]["capture"]["path"]
    key = f"scenes.{name}.capture.path"
    if not Path(path).is_dir():
        raise WorkflowError(
            f"config: scene {name!r}: {key}: capture directory {path!r} does not exist "
            f"(relative paths are relative to the working directory {os.getcwd()})"
        )
    if not Path(path, "mesh.ply").is_file():
        raise WorkflowError(
            f"config: scene {name!r}: {key}: {path!r} has no mesh.ply "
            "(a mesh, or a point cloud with normals)"
        )
    if cameras_file(path) is None:
        raise WorkflowError(
            f"config: scene {name!r}: {key}: {path!r} has no cameras: expected sparse/ "
            "(a COLMAP model: cameras and images, .txt or .bin) or transforms.json"
        )


for _name in SYNTHETIC:
    _check_generator_config(_name)
for _name in CAPTURES:
    _check_capture(_name)


# ---------------------------------------------------------------------------- targets


def scene_targets(scene):
    """Every artifact the workflow makes for one scene (what `rule all` asks for)."""
    targets = [
        f"results/{scene}/cameras",
        f"results/{scene}/geometry",
        f"results/{scene}/gradients",
    ]
    if is_synthetic(scene):
        targets += [
            f"results/{scene}/capture",
            f"results/{scene}/features.json",
            f"results/{scene}/renders",
            f"results/{scene}/export",
        ]
    return targets


# ---------------------------------------------------------------------------- input functions


def capture_dir(wildcards):
    """The scene's capture: what the synthesize rule writes, or the user's directory."""
    if is_synthetic(wildcards.scene):
        return f"results/{wildcards.scene}/capture"
    return SCENES[wildcards.scene]["capture"]["path"]


def capture_path(name):
    """Input function for <capture>/<name>. A synthetic capture is one directory output, so the
    rule depends on that directory; a user's capture on the file itself, so that editing it
    re-runs the rules that read it."""

    def function(wildcards):
        if is_synthetic(wildcards.scene):
            return capture_dir(wildcards)
        return os.path.join(capture_dir(wildcards), name)

    return function


def capture_cameras(wildcards):
    """The capture's cameras: a COLMAP model directory or a transforms.json file."""
    if is_synthetic(wildcards.scene):
        return os.path.join(capture_dir(wildcards), "sparse")
    return os.path.join(capture_dir(wildcards), cameras_file(capture_dir(wildcards)))


def capture_cameras_input(wildcards):
    if is_synthetic(wildcards.scene):
        return capture_dir(wildcards)
    return capture_cameras(wildcards)


def scene_dir(wildcards):
    """The scene directory (scene.json) that features, render and export read. Until the
    bake stage exists that is the synthetic scene's ground truth; swap it here for
    results/{scene}/scene.
    """
    if not is_synthetic(wildcards.scene):
        raise WorkflowError(
            f"scene {wildcards.scene!r} is a capture: features, render and export need a scene "
            "directory, which only synthetic scenes have until the bake stage exists"
        )
    return f"results/{wildcards.scene}/capture/ground_truth/scene"


def scene_input(wildcards):
    """The output that holds scene_dir(wildcards): what features, render and export depend on."""
    scene_dir(wildcards)
    return f"results/{wildcards.scene}/capture"


# ---------------------------------------------------------------------------- params


def synthesize_config(wildcards):
    """The generator overrides as one line of JSON (JSON is YAML), fed to --config on stdin."""
    return json.dumps(SCENES[wildcards.scene]["synthetic"]["config"], sort_keys=True)


def analysis_options(wildcards):
    """features' analysis settings as flags (--bounce-fraction 0.01 ...)."""
    keys = ("bounce_fraction", "specular_threshold", "max_bounces", "min_bounces")
    return " ".join(
        f"--{key.replace('_', '-')} {config['features'][key]}" for key in keys
    )


def feature_overrides(wildcards):
    """`--set key=value` for each forced feature (values as JSON: true, false, 3)."""
    overrides = config["features"]["overrides"]
    return " ".join(
        f"--set {shlex.quote(f'{key}={json.dumps(value)}')}"
        for key, value in sorted(overrides.items())
    )


def geometry_options(wildcards):
    """Atlas size: a texel density if one is given, else the fixed resolution."""
    geometry = config["geometry"]
    if geometry["texels_per_meter"] is not None:
        size = f"--texels-per-meter {geometry['texels_per_meter']}"
    else:
        size = f"--atlas-resolution {geometry['atlas_resolution']}"
    return (
        f"--target-faces {geometry['target_faces']} {size} "
        f"--padding {geometry['padding']} --poisson-depth {geometry['poisson_depth']}"
    )


def scene_poses(wildcards):
    """The poses of a duplicates scene's copies (DESIGN.md: duplicates/poses.json): the
    synthetic scene's truth until the duplicates stage writes its own."""
    synthetic = SCENES[wildcards.scene].get("synthetic", {})
    if synthetic.get("kind") == "duplicates":
        return f"results/{wildcards.scene}/capture/ground_truth/poses.json"
    return None


def export_options(wildcards):
    """invrender export's flags: --usdc, --no-instancing, and the poses of duplicates."""
    options = []
    if config["export"]["usdc"]:
        options.append("--usdc")
    if not config["export"]["instancing"]:
        options.append("--no-instancing")
    poses = scene_poses(wildcards)
    if poses:
        options.append(f"--poses {shlex.quote(poses)}")
    return " ".join(options)


def device_option(wildcards):
    device = config["device"]
    return f"--device {shlex.quote(device)}" if device else ""


# ---------------------------------------------------------------------------- resources

CPU_DEVICE_WORDS = ("pocl", "portable computing", "pthread", "cpu")


def gpu_request(wildcards):
    """GPUs a ray-tracing job asks for (resource `gpu`, which snakemake-executor-plugin-slurm
    turns into --gpus=N): one when config["device"] names a device that is not a CPU one. With
    device null the job uses whatever the node has, so it asks for none."""
    device = (config["device"] or "").lower()
    if not device or any(word in device for word in CPU_DEVICE_WORDS):
        return 0
    return 1

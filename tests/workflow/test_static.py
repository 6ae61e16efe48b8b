"""The workflow's frame, without running a job: lint, formatting, the demo's DAG, the config
schema, its generated documentation and its errors, the cluster profile, and the conda
environments' pins. (The checks of each mode's captures are in test_modes.py.)"""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys

import pytest
import tomllib
import yaml
from workflow_helpers import FULL_RUN_JOBS, REPO, TEST_CONFIG, job_counts, snakemake

DEMO_CONFIG = REPO / "config" / "config.yaml"
SCHEMA = REPO / "workflow" / "schemas" / "config.schema.yaml"
SLURM_PROFILE = REPO / "workflow" / "profiles" / "slurm"
# The rules of the demo's DAG before the segment checkpoint has run (what --rulegraph and a dry
# run show); duplicates_crop, one job per instance, joins once it has.
RULES = {"synthesize", "cameras", "geometry", "gradients", "milo_train", "bake", "bake_duplicates"}
RULES |= {"segment", "duplicates", "duplicates_material", "features", "render", "export", "evaluate"}
RULES |= {"evaluate_duplicates", "edit", "recovery_run", "accuracy", "summary", "room_box", "room_lights"}
RULES |= {"bake_room", "evaluate_room", "room_objects", "room_materials"}
CHECKPOINT_RULES = {"duplicates_crop"}
RAY_TRACING_RULES = {"synthesize", "features", "render", "gradients", "milo_train", "duplicates_material"}
RAY_TRACING_RULES |= {"evaluate", "evaluate_duplicates", "edit", "recovery_run", "accuracy", "room_lights"}
RAY_TRACING_RULES |= {"evaluate_room", "room_objects", "room_materials"}


def test_lint_is_clean(tmp_path):
    result = snakemake(tmp_path, "--lint")
    assert "Congratulations, your workflow is in a good condition!" in result.stdout
    assert "Lints for" not in result.stdout and "warning" not in result.stdout.lower(), result.stdout


def test_snakefmt_check():
    paths = [REPO / "Snakefile", REPO / "workflow" / "rules"]
    result = subprocess.run(
        [sys.executable, "-m", "snakefmt", "--check", *map(str, paths)],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    assert result.returncode == 0, result.stdout


@pytest.mark.parametrize("command", [["format", "--check", "--diff"], ["check"]], ids=["format", "lint"])
def test_python_follows_ruff(command):
    """The formatter's style and the lint (pyproject.toml [tool.ruff]) over the package and tests."""
    result = subprocess.run(
        [sys.executable, "-m", "ruff", *command, "workflow", "tests"],
        cwd=REPO,
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
    )
    assert result.returncode == 0, result.stdout[-3000:]


def test_dry_run_of_the_demo(tmp_path):
    result = snakemake(tmp_path, "-n", config=DEMO_CONFIG)
    # the demo has no recovery sweep (config/accuracy-sweep.yaml adds it: the test below); its third
    # scene, the living room photo, is synthesized and gets its room box, lights, objects and
    # materials and its room scene (bake_room), with features, render and export on it, scored
    expected = FULL_RUN_JOBS | {"recovery_run": 0, "room_box": 1, "room_lights": 1, "room_objects": 1}
    expected |= {"room_materials": 1, "bake_room": 1, "evaluate_room": 1}
    for rule in ("synthesize", "features", "render", "export"):
        expected[rule] = FULL_RUN_JOBS[rule] + 1
    assert job_counts(result.stdout) == {rule: n for rule, n in expected.items() if n}


def test_the_accuracy_sweep_config_adds_the_recovery_runs(tmp_path):
    """config/accuracy-sweep.yaml on top of the demo: 5 runs of the room (the configured texels
    model and MILO-Net's presets) and 3 of the material stage."""
    sweep = DEMO_CONFIG.with_name("accuracy-sweep.yaml")
    result = snakemake(tmp_path, "-n", config=[DEMO_CONFIG, sweep])
    assert job_counts(result.stdout)["recovery_run"] == 8


def test_every_rule_is_known():
    """Each rule the .smk files define is in RULES or CHECKPOINT_RULES (so the tests below see
    every rule), and nothing is in both."""
    defined = set()
    for smk in [REPO / "Snakefile", *(REPO / "workflow" / "rules").glob("*.smk")]:
        defined |= set(re.findall(r"(?m)^(?:rule|checkpoint) (\w+):", smk.read_text()))
    assert defined == {"all"} | RULES | CHECKPOINT_RULES and not RULES & CHECKPOINT_RULES


def test_rulegraph_picture_is_current(tmp_path):
    """docs/rulegraph.svg shows every rule (regenerate it as docs/workflow.md says when rules change);
    the recovery sweep's rule is there with config/accuracy-sweep.yaml."""
    result = snakemake(tmp_path, "--rulegraph", config=[DEMO_CONFIG, DEMO_CONFIG.with_name("accuracy-sweep.yaml")])
    rules = set(re.findall(r'label = "([a-z_]+)"', result.stdout))
    svg = (REPO / "docs" / "rulegraph.svg").read_text()
    assert rules == {"all"} | RULES
    for rule in rules:
        assert f">{rule}</text>" in svg


# ---------------------------------------------------------------------------- the config


def _walk(schema, path="config"):
    yield path, schema
    for key, sub in schema.get("properties", {}).items():
        yield from _walk(sub, f"{path}.{key}")
    if isinstance(schema.get("additionalProperties"), dict):
        yield from _walk(schema["additionalProperties"], f"{path}.<name>")


def test_schema_documents_and_closes_every_key():
    schema = yaml.safe_load(SCHEMA.read_text())
    for path, node in _walk(schema):
        assert node.get("description"), f"{path}: no description"
        if "properties" in node:
            assert node.get("additionalProperties") is False, f"{path}: a typo'd key would pass"
    scene = schema["properties"]["scenes"]["additionalProperties"]["properties"]
    modes = scene["mode"]["enum"]
    assert set(scene["mode"]["x-stages"]) == set(modes)
    for key, node in scene["capture"]["properties"].items():
        assert set(node.get("x-modes", modes)) <= set(modes), key


def _config_readme():
    spec = importlib.util.spec_from_file_location("config_readme", REPO / "workflow" / "schemas" / "config_readme.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_config_readme_is_generated_from_the_schema():
    """config/README.md is what the generator makes of the schema: every key once, with its type,
    default and description, so that the two cannot drift apart."""
    generator = _config_readme()
    text = generator.render()
    assert (REPO / "config" / "README.md").read_text() == text, "run python workflow/schemas/config_readme.py"
    schema = yaml.safe_load(SCHEMA.read_text())
    rows = re.findall(r"(?m)^\| `([^`]+)` \| ([^|]*) \| ([^|]*) \|", text)
    assert [row[0] for row in rows[3:]] == [key for key, _, _ in generator.keys(schema)]  # after the 3 modes
    documented = {key: (kind, default) for key, kind, default in rows}
    assert documented["geometry.target_faces"] == ("integer, >= 4", "`20000`")
    assert documented["scenes.<name>.capture.path"] == ("string", "required")
    assert documented["scenes.<name>.mode"][0] == "`multiview` or `duplicates` or `room`"
    assert "*room only.*" in text.split("`scenes.<name>.capture.depth`")[1].split("\n")[0]


def test_demo_config_is_valid_and_complete():
    """The demo config spells out every top-level setting, so it doubles as a reference."""
    schema = yaml.safe_load(SCHEMA.read_text())
    demo = yaml.safe_load(DEMO_CONFIG.read_text())
    assert set(demo) == set(schema["properties"])
    assert {s["synthetic"]["kind"] for s in demo["scenes"].values()} == {"room", "duplicates", "room_photo"}


def test_config_readme_generator_rejects_a_template_without_its_tables(tmp_path):
    template = tmp_path / "template.md"
    template.write_text("# Configuring\n\n{{keys}}\n")
    with pytest.raises(ValueError, match="modes"):
        _config_readme().render(template_path=template)


BAD_CONFIGS = {
    "typo in a section": (
        {"geometry": {"target_face": 1000}},
        [
            "config: geometry.target_face: unknown key; allowed: target_faces, atlas_resolution, texels_per_meter, "
            "padding, poisson_depth"
        ],
    ),
    "typo at the top": (
        {"render": {"spp": 4}, "scene": {}},
        [
            "config: scene: unknown key; allowed: device, scenes, geometry, duplicates, features, gradients, render, "
            "room_objects, duplicates_material, milo, evaluate, accuracy, edit, export, bake_room, room_materials"
        ],
    ),
    "typo in a scene": (
        {"scenes": {"room": {"synthetic": {"kind": "room", "sed": 3}}}},
        ["config: scenes.room.synthetic.sed: unknown key; allowed: kind, spp, seed, config"],
    ),
    "typo in a generator override": (
        {"scenes": {"room": {"synthetic": {"kind": "room", "config": {"camras": {}}}}}},
        ["scenes.room.synthetic.config", "camras"],
    ),
    "generator override of the wrong type": (
        {"scenes": {"room": {"synthetic": {"kind": "room", "config": {"cameras": {"count": "six"}}}}}},
        ["config: scenes.room.synthetic.config.cameras.count: 'six' is not of type 'integer'"],
    ),
    "generator vector of the wrong length": (
        {"scenes": {"room": {"synthetic": {"kind": "room", "config": {"size": [4.0, 2.6]}}}}},
        ["config: scenes.room.synthetic.config.size: [4.0, 2.6] is too short"],
    ),
    "wrong type": ({"render": {"spp": "many"}}, ["config: render.spp: 'many' is not of type 'integer'"]),
    "out of range": ({"render": {"spp": 0}}, ["config: render.spp: 0 is less than the minimum of 1"]),
    "unknown kind": (
        {"scenes": {"room": {"synthetic": {"kind": "castle"}}}},
        ["config: scenes.room.synthetic.kind: 'castle' is not allowed; allowed: room, duplicates, room_photo"],
    ),
    "missing capture": (
        {"scenes": {"kitchen": {"capture": {"path": "no/such/capture"}}}},
        ["'kitchen'", "scenes.kitchen.capture.path", "no/such/capture"],
    ),
    "unknown mode": (
        {"scenes": {"room": {"mode": "panorama", "synthetic": {"kind": "room"}}}},
        ["config: scenes.room.mode: 'panorama' is not allowed; allowed: multiview, duplicates, room"],
    ),
    "mode against the generator's kind": (
        {"scenes": {"cans": {"mode": "room", "synthetic": {"kind": "duplicates"}}}},
        ["'cans'", "scenes.cans.mode", "'room'", "'duplicates'"],
    ),
    "synthetic and capture at once": (
        {"scenes": {"room": {"synthetic": {"kind": "room"}, "capture": {"path": "."}}}},
        ["config: scenes.room: give one of synthetic or capture (got synthetic and capture)"],
    ),
    "bounds in the wrong order": (
        {"features": {"min_bounces": 5, "max_bounces": 3}},
        ["config: features.min_bounces: 5 is more than features.max_bounces (3)"],
    ),
    "contradictory feature overrides": (
        {"features": {"overrides": {"window": True, "environment": False}}},
        ["config: features.overrides: window needs environment"],
    ),
    "no such device": ({"device": "NoSuchGPU"}, ["config: device: no OpenCL device matches 'NoSuchGPU'; available: "]),
}


def assert_one_message(output: str, expected: list[str]):
    """The output is snakemake's header, the one-line message and the lines snakemake adds
    saying where in common.smk it was raised: a few lines, and nothing of the schema."""
    for text in expected:
        assert text in output, output[-3000:]
    lines = output.strip().splitlines()
    assert len(lines) <= 5, output[-3000:]
    assert "description" not in output and "Failed validating" not in output, output[-3000:]


@pytest.mark.parametrize("name", BAD_CONFIGS)
def test_bad_config_stops_before_any_job(tmp_path, name):
    override, expected = BAD_CONFIGS[name]
    config = tmp_path / "override.yaml"
    config.write_text(yaml.safe_dump(override))
    result = snakemake(tmp_path, "--cores", "1", config=[TEST_CONFIG, config], check=False)
    assert result.returncode != 0
    assert_one_message(result.stdout, expected)
    assert not (tmp_path / "results").exists()  # no job ran


def test_typo_on_the_command_line_is_one_message(tmp_path):
    """Issue 10, defect 10: a typo'd key was named, then followed by some 50 lines of schema."""
    result = snakemake(tmp_path, "-n", "--config", "scenes={room: {synthetic: {kind: room, sed: 3}}}", check=False)
    assert result.returncode != 0
    assert_one_message(result.stdout, ["config: scenes.room.synthetic.sed: unknown key; allowed: kind, spp, seed"])


def _tree(folder):
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.mark.parametrize("dry_run", [True, False])
def test_unknown_device_stops_before_any_job_and_keeps_previous_outputs(tmp_path, dry_run):
    """Issue 10, defect 7: `--config device=NoSuchGPU` passed the checks, and the synthesize job
    it re-ran failed with a traceback after snakemake had deleted the good capture. The message
    lists the devices render/device.py sees."""
    from invrender.render.device import all_devices, describe

    capture = tmp_path / "results" / "room" / "capture"
    (capture / "images").mkdir(parents=True)
    (capture / "images" / "view_000.png").write_bytes(b"a previous output")
    before = _tree(tmp_path / "results")
    args = ["-n"] if dry_run else ["--cores", "1"]
    result = snakemake(tmp_path, *args, "--config", "device=NoSuchGPU", check=False)
    assert result.returncode != 0
    listing = "; ".join(describe(d) for d in all_devices())
    assert_one_message(result.stdout, [f"config: device: no OpenCL device matches 'NoSuchGPU'; available: {listing}"])
    assert _tree(tmp_path / "results") == before


def test_device_from_the_environment_is_checked_and_a_present_one_passes(tmp_path):
    from invrender.render.device import all_devices

    result = snakemake(tmp_path, "-n", check=False, env={"INVRENDER_DEVICE": "NoSuchGPU"})
    assert result.returncode != 0
    assert_one_message(result.stdout, ["config: $INVRENDER_DEVICE (config device is null): no OpenCL device matches"])
    present = all_devices()[0].name.split()[0]  # "pthread-AMD": a plain YAML string
    assert job_counts(snakemake(tmp_path, "-n", "--config", f"device={present}").stdout)["synthesize"] == 2


def test_capture_without_cameras_is_named(tmp_path):
    capture = tmp_path / "mine"
    capture.mkdir()
    (capture / "mesh.ply").write_text("ply\n")
    config = tmp_path / "override.yaml"
    config.write_text(yaml.safe_dump({"scenes": {"mine": {"capture": {"path": "mine"}}}}))
    result = snakemake(tmp_path, "-n", config=config, check=False)
    assert result.returncode != 0
    assert "scenes.mine.capture.path" in result.stdout and "transforms.json" in result.stdout


def test_nested_config_overrides_on_the_command_line(tmp_path):
    """--config hands nested values over as strings; numbers are read back as numbers."""
    result = snakemake(tmp_path, "-n", "--config", "geometry={target_faces: 1000}", "render={spp: 2}")
    assert job_counts(result.stdout)["geometry"] == 2
    assert "--target-faces 1000" in snakemake(tmp_path, "-n", "-p", "--config", "geometry={target_faces: 1000}").stdout


# ---------------------------------------------------------------------------- the cluster profile


def _resources_by_rule(output: str) -> dict[str, str]:
    rules = {}
    for rule, resources in re.findall(r"(?m)^(?:rule|checkpoint) (\w+):\n(?:    .*\n)*?    resources: (.*)", output):
        rules[rule] = resources
    return rules


@pytest.mark.parametrize("device, gpus", [("NVIDIA", 1), ("pocl", 0), (None, 0)])
def test_slurm_profile_requests_gpus_for_ray_tracing(tmp_path, device, gpus):
    import snakemake_executor_plugin_slurm  # noqa: F401  (a test extra: the profile needs it)

    args = ["-n", "--workflow-profile", SLURM_PROFILE]
    if device:
        args += ["--config", f"device={device}"]
    # the toy scenes and a room photo (config files merge scene by scene): every mode's rules
    result = snakemake(tmp_path, *args, config=[TEST_CONFIG, TEST_CONFIG.with_name("room_photo.yaml")])
    resources = _resources_by_rule(result.stdout)
    resources.pop("all", None)
    assert set(resources) == RULES
    for rule, line in resources.items():
        assert "mem_mb=" in line and "runtime=" in line and "cpus_per_task=" in line
        if rule in RAY_TRACING_RULES:
            assert f"gpu={gpus}" in line, (rule, line)
        else:
            assert "gpu=" not in line, (rule, line)


# ---------------------------------------------------------------------------- conda environments


def _requirement(spec: str) -> tuple[str, str]:
    """("name", "the version part") of a PEP 508 requirement such as "numpy>=1.26"."""
    match = re.match(r"^([A-Za-z0-9][A-Za-z0-9._-]*)\s*(.*)$", spec.strip())
    return match.group(1).lower().replace("_", "-"), match.group(2).replace(" ", "")


def test_conda_envs_pin_like_pyproject():
    project = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]
    pins = dict(_requirement(s) for s in project["dependencies"])
    for extra in project.get("optional-dependencies", {}).values():
        pins.update(_requirement(s) for s in extra)
    envs = sorted((REPO / "envs").glob("*.yaml"))
    assert {e.stem for e in envs} >= {"render", "geometry", "workflow"}
    for env in envs:
        dependencies = yaml.safe_load(env.read_text())["dependencies"]
        pip = next(d["pip"] for d in dependencies if isinstance(d, dict) and "pip" in d)
        assert "-e ${INVRENDER_SOURCE}" in pip, f"{env.name}: does not install the package"
        listed = [_requirement(s) for s in pip if not s.startswith("-")]
        assert ("torch", "==2.13.0") in listed, f"{env.name}: torch must be pinned (an unpinned torch pulls CUDA)"
        for name, version in listed:
            assert name in pins, f"{env.name}: {name} is not a dependency in pyproject.toml"
            assert version == pins[name], f"{env.name}: {name}{version!r} differs from pyproject's {name}{pins[name]}"


def test_every_rule_uses_a_conda_env_that_exists():
    for smk in (REPO / "workflow" / "rules").glob("*.smk"):
        for env in re.findall(r'conda:\s*\n\s*"([^"]+)"', smk.read_text()):
            assert (smk.parent / env).resolve().is_file(), f"{smk.name}: {env}"

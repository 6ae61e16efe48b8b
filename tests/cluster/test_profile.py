"""The slurm profile's resources against the workflow's rules, without a cluster: every rule SLURM
runs has a measured request (mem_mb, runtime, cpus_per_task as positive integers), no request
names a rule, group or resource that does not exist, and the script that derives the requests
from benchmark records applies the headroom its docstring states."""

from __future__ import annotations

import copy
import importlib.util
import re
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
PROFILE = REPO / "workflow" / "profiles" / "slurm"
# The resources snakemake-executor-plugin-slurm reads (its docs' "Resources" list), and
# snakemake's own.
PLUGIN_RESOURCES = {
    "mem_mb",
    "mem_mb_per_cpu",
    "runtime",
    "cpus_per_task",
    "cpus_per_gpu",
    "tasks",
    "nodes",
    "slurm_partition",
    "slurm_account",
    "constraint",
    "qos",
    "gpu",
    "gpu_model",
    "gres",
    "slurm_extra",
    "tmpdir",
    "disk_mb",
}
MEASURED = ("mem_mb", "runtime", "cpus_per_task")


def _resources_module():
    spec = importlib.util.spec_from_file_location("slurm_resources", PROFILE / "resources.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def workflow_rules() -> tuple[set[str], set[str], set[str]]:
    """(rules and checkpoints, groups, localrules) as the Snakefile and workflow/rules/*.smk
    declare them."""
    sources = [REPO / "Snakefile", *sorted((REPO / "workflow" / "rules").glob("*.smk"))]
    text = "\n".join(p.read_text() for p in sources)
    rules = set(re.findall(r"(?m)^(?:rule|checkpoint) (\w+):", text))
    groups = set(re.findall(r'(?m)^    group:\n        "(\w+)"', text))
    local = set()
    for block in re.findall(r"(?m)^localrules:\n((?:    .*\n)+)", text):
        local |= set(re.findall(r"\w+", block))
    return rules, groups, local


def _positive_int(value) -> bool:
    return isinstance(value, int) and not isinstance(value, bool) and value > 0


def profile_problems(profile: dict) -> list[str]:
    """What is wrong with the profile's resources, one line each; [] when nothing is."""
    rules, groups, local = workflow_rules()
    from_config = _resources_module().RUNTIME_FROM_CONFIG
    problems = []
    default = profile.get("default-resources", {})
    for key in MEASURED:
        if not _positive_int(default.get(key)):
            problems.append(f"default-resources: {key}: {default.get(key)!r} is not a positive integer")
    requests = profile.get("set-resources", {})
    for rule, request in requests.items():
        if rule not in rules:
            problems.append(f"set-resources: {rule}: no such rule")
        elif rule in local:
            problems.append(f"set-resources: {rule}: a localrule, which SLURM never runs")
        if not isinstance(request, dict):
            problems.append(f"set-resources: {rule}: {request!r} is not a mapping")
            continue
        for key in set(request) - PLUGIN_RESOURCES:
            problems.append(f"set-resources: {rule}: {key}: not a resource the SLURM executor reads")
        for key in MEASURED:
            if key == "runtime" and rule in from_config:
                if key in request:
                    problems.append(f"set-resources: {rule}: runtime: follows the config, not the profile")
            elif not _positive_int(request.get(key)):
                problems.append(f"set-resources: {rule}: {key}: {request.get(key)!r} is not a positive integer")
    for rule in sorted(rules - local - set(requests)):
        problems.append(f"set-resources: {rule}: no measured request")
    for entry in profile.get("group-components", []):
        group, _, count = str(entry).partition("=")
        if group not in groups:
            problems.append(f"group-components: {entry}: no rule has group {group!r}")
        if not count.isdigit() or int(count) < 1:
            problems.append(f"group-components: {entry}: {count!r} is not a positive integer")
    for rule in profile.get("set-threads", {}):
        if rule not in rules:
            problems.append(f"set-threads: {rule}: no such rule")
    return problems


def _profile() -> dict:
    return yaml.safe_load((PROFILE / "config.yaml").read_text())


def test_profile_resources_are_well_formed():
    assert profile_problems(_profile()) == []


def test_trivial_steps_run_on_the_login_node():
    """localrules: the target rule and the bakes (seconds, ~130 MB: a queue's wait would be
    most of their time)."""
    _, _, local = workflow_rules()
    assert local == {"all", "bake", "bake_duplicates"}


def _set(path, value):
    def mutate(profile):
        node = profile
        for key in path[:-1]:
            node = node[key]
        node[path[-1]] = value

    return mutate


def _drop(rule):
    return lambda profile: profile["set-resources"].pop(rule)


@pytest.mark.parametrize(
    "mutate, problem",
    [
        (_set(["set-resources", "render", "mem_mb"], "8G"), "set-resources: render: mem_mb: '8G' is not a positive"),
        (_set(["set-resources", "render", "runtime"], 0), "set-resources: render: runtime: 0 is not a positive"),
        (_set(["set-resources", "render", "cpus_per_task"], 1.5), "render: cpus_per_task: 1.5 is not"),
        (_set(["set-resources", "rendr"], {"mem_mb": 1, "runtime": 1, "cpus_per_task": 1}), "rendr: no such rule"),
        (_set(["set-resources", "render", "memory"], 4000), "render: memory: not a resource"),
        (_set(["set-resources", "milo_train", "runtime"], 30), "milo_train: runtime: follows the config"),
        (_set(["set-resources", "bake"], {"mem_mb": 1, "runtime": 1, "cpus_per_task": 1}), "bake: a localrule"),
        (_drop("segment"), "set-resources: segment: no measured request"),
        (_set(["group-components"], ["duplicate_crops=8"]), "no rule has group 'duplicate_crops'"),
        (_set(["group-components"], ["duplicates_crops=0"]), "'0' is not a positive integer"),
        (_set(["default-resources", "mem_mb"], None), "default-resources: mem_mb: None"),
    ],
    ids=["unit", "zero", "float", "rule", "key", "milo", "local", "missing", "group", "count", "default"],
)
def test_malformed_profiles_are_named(mutate, problem):
    profile = copy.deepcopy(_profile())
    mutate(profile)
    problems = profile_problems(profile)
    assert any(problem in p for p in problems), problems


def test_requests_from_benchmark_records(tmp_path, capsys):
    """Two scenes' records of one rule and a per-instance rule's: the worst case over them,
    with the headroom (2 x max_rss to 500 MB, 10 x s in minutes, cpu_time / s rounded up)."""
    header = "s\th:m:s\tmax_rss\tmax_vms\tmax_uss\tmax_pss\tio_in\tio_out\tmean_load\tcpu_time\n"
    files = {
        "a/benchmarks/render.tsv": "38.2\t0:00:38\t179.7\t1\t1\t1\t0\t0\t78\t29.7\n",
        "b/benchmarks/render.tsv": "95.0\t0:01:35\t610.0\t1\t1\t1\t0\t0\t150\t150.1\n",
        "b/benchmarks/duplicates_crop/001.tsv": "19.2\t0:00:19\t541.9\t1\t1\t1\t0\t0\t26\t5.1\n",
        "b/benchmarks/milo_train.tsv": "135.8\t0:02:15\t729.0\t1\t1\t1\t0\t0\t123\t167.5\n",
    }
    for name, row in files.items():
        (tmp_path / name).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / name).write_text(header + row)
    module = _resources_module()
    found = module.records([tmp_path])
    assert sorted(found) == ["duplicates_crop", "milo_train", "render"]
    assert module.resources(found["render"], "render") == {"mem_mb": 1500, "runtime": 16, "cpus_per_task": 2}
    assert module.resources(found["duplicates_crop"], "duplicates_crop") == {
        "mem_mb": 1500,
        "runtime": 5,
        "cpus_per_task": 1,
    }
    assert module.resources(found["milo_train"], "milo_train") == {"mem_mb": 1500, "cpus_per_task": 2}
    assert module.main([str(tmp_path)]) == 0
    printed = yaml.safe_load(capsys.readouterr().out)
    assert printed["set-resources"]["render"] == {"mem_mb": 1500, "runtime": 16, "cpus_per_task": 2}

"""The workflow on a real (one-node) SLURM cluster through workflow/profiles/slurm and
snakemake-executor-plugin-slurm: every job goes through sbatch with the resources the profile
asks for, the outputs equal a local run's, a job cancelled with scancel is re-run by the next
invocation while finished jobs are not, and a failing job's message names its logs.

One test, in steps, because the steps share one cluster and one run's outputs (a session fixture
per xdist worker would start a second cluster). The config (config.yaml beside this file) is the
duplicates scene at a small size, up to its per-instance crops.
"""

from __future__ import annotations

import re
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

REPO = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(REPO / "tests" / "workflow"))
from workflow_helpers import end_process, snakemake_env  # noqa: E402

CONFIG = Path(__file__).with_name("config.yaml")
PROFILE = REPO / "workflow" / "profiles" / "slurm"
LOCAL_PROFILE = REPO / "workflow" / "profiles" / "local"
INSTANCES = ("001", "002", "003")
TARGETS = [f"results/boxes/crops/instance_{i}{suffix}" for i in INSTANCES for suffix in (".npz", ".features.npz")]
GROUP = "duplicates_crops"
# What a run writes besides its outputs: logs and benchmark records differ from run to run.
NOT_OUTPUTS = ("logs", "benchmarks")


def _command(workdir, *args) -> list[str]:
    return [
        sys.executable,
        "-m",
        "snakemake",
        "-s",
        str(REPO / "Snakefile"),
        "--directory",
        str(workdir),
        "--configfile",
        str(CONFIG),
        *map(str, args),
    ]


def _slurm_args(*targets):
    # The first status check after a second, not 40 (the plugin's default, kind to a busy
    # cluster's sacct): the test's jobs take seconds.
    return ["--workflow-profile", PROFILE, "--slurm-init-seconds-before-status-checks", "1", *targets]


@pytest.fixture
def children():
    """The snakemake processes a test starts: interrupted (as Ctrl-C would: snakemake then
    cancels its SLURM jobs) if the test ends before they do."""
    started: list[subprocess.Popen] = []
    yield started
    for process in started:
        end_process(process, signal.SIGINT, timeout=120)


def _popen(cluster, cmd, children) -> subprocess.Popen:
    process = subprocess.Popen(
        cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env={**snakemake_env(), **cluster.env}
    )
    children.append(process)
    return process


def _finish(process: subprocess.Popen, timeout=900) -> str:
    out, _ = process.communicate(timeout=timeout)
    return out


def _run(cluster, cmd, children, timeout=900) -> subprocess.CompletedProcess:
    process = _popen(cluster, cmd, children)
    out = _finish(process, timeout)
    return subprocess.CompletedProcess(cmd, process.returncode, out)


def announced_jobs(output: str) -> dict[str, dict[str, int]]:
    """{"local": {rule: n}, "remote": {rule: n}} of the jobs a snakemake run announced: a job
    snakemake runs itself is printed as `localrule x:` (or `localcheckpoint x:`), one it hands
    to the executor as `rule x:`, also inside a group job's listing (indented)."""
    jobs: dict[str, dict[str, int]] = {"local": {}, "remote": {}}
    for local, rule in re.findall(r"(?m)^\s*(local)?(?:rule|checkpoint) (\w+):$", output):
        where = jobs["local" if local else "remote"]
        where[rule] = where.get(rule, 0) + 1
    return jobs


def sacct_jobs(cluster, after: int) -> list[dict[str, str]]:
    """The cluster's jobs with an id above `after`: id, comment (the executor's
    rule_<rule>_wildcards_<...>), requested memory, time limit and CPUs, state."""
    fields = ["JobID", "JobName", "Comment", "ReqMem", "Timelimit", "ReqCPUS", "State"]
    out = cluster.run("sacct", "-X", "-n", "-P", "-S", "2000-01-01", "-o", ",".join(fields))
    jobs = [dict(zip(fields, line.split("|"))) for line in out.splitlines() if line.strip()]
    return [job for job in jobs if int(job["JobID"]) > after]


def last_job_id(cluster) -> int:
    return max([int(job["JobID"]) for job in sacct_jobs(cluster, 0)], default=0)


def profile_request(rule: str) -> dict[str, int]:
    profile = yaml.safe_load((PROFILE / "config.yaml").read_text())
    request = dict(profile["default-resources"])
    request.update(profile["set-resources"].get(rule, {}))
    return {key: request[key] for key in ("mem_mb", "runtime", "cpus_per_task")}


def sacct_request(job) -> dict[str, int]:
    hours, minutes, seconds = map(int, job["Timelimit"].split(":"))
    assert job["ReqMem"].endswith("M"), job
    return {
        "mem_mb": int(job["ReqMem"][:-1]),
        "runtime": hours * 60 + minutes + seconds // 60,
        "cpus_per_task": int(job["ReqCPUS"]),
    }


def job_rule(job) -> str:
    """The rule (or group) the executor named in the job's comment."""
    match = re.match(r"rule_(\w+?)(?:_wildcards_.*)?$", job["Comment"])
    assert match, f"SLURM job {job['JobID']} has no rule in its comment: {job}"
    return match.group(1)


def assert_all_through_slurm(output: str, jobs: list[dict[str, str]]):
    """Each job the run announced went through sbatch: none ran locally (the test's targets
    need no localrule), and sacct holds one job per rule job, one per group job."""
    announced = announced_jobs(output)
    assert announced["local"] == {}, f"jobs bypassed SLURM: {announced['local']}\n{output[-4000:]}"
    submitted: dict[str, int] = {}
    for job in jobs:
        rule = job_rule(job)
        submitted[rule] = submitted.get(rule, 0) + 1
    expected = dict(announced["remote"])
    crops = expected.pop("duplicates_crop", 0)
    if crops:
        expected[f"{GROUP}_duplicates_crop"] = 1  # the group's comment: group, then its rules
    assert submitted == expected, f"sbatch jobs {submitted} != jobs snakemake ran {announced['remote']}"


def assert_requests(jobs: list[dict[str, str]], crops: int):
    for job in jobs:
        rule = job_rule(job)
        if rule.startswith(GROUP):
            # a group runs its crops side by side: their CPUs and memory add up, runtime is one's
            one = profile_request("duplicates_crop")
            expected = {
                "mem_mb": crops * one["mem_mb"],
                "runtime": one["runtime"],
                "cpus_per_task": crops * one["cpus_per_task"],
            }
        else:
            expected = profile_request(rule)
        assert sacct_request(job) == expected, f"SLURM job {job['JobID']} ({rule}): {job}"


def _wait_for_running_group(cluster, logs: Path, process: subprocess.Popen, timeout=600) -> str:
    """The SLURM id of the crops' group job once it runs and a crop has started (its log
    exists): then it is mid-run."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        assert process.poll() is None, f"snakemake ended before the group job ran:\n{_finish(process)[-4000:]}"
        for line in cluster.run("squeue", "-h", "-o", "%i|%T|%k").splitlines():
            job_id, state, comment = line.split("|", 2)
            if comment.startswith(f"rule_{GROUP}") and state == "RUNNING" and any(logs.glob("*.log")):
                return job_id
        time.sleep(0.3)
    raise AssertionError(f"the group job did not run within {timeout} s:\n{cluster.log_tails()}")


def _outputs(workdir: Path) -> list[str]:
    """The files under results/boxes/ that the stages wrote (not logs, not benchmarks),
    relative to it."""
    results = workdir / "results" / "boxes"
    files = [p.relative_to(results) for p in results.rglob("*") if p.is_file()]
    return sorted(str(p) for p in files if p.parts[0] not in NOT_OUTPUTS)


def _crop_files(instance: str) -> list[str]:
    return [t for t in TARGETS if f"instance_{instance}." in t]


def _mtimes(root: Path) -> dict[str, int]:
    return {str(p.relative_to(root)): p.stat().st_mtime_ns for p in sorted(root.rglob("*")) if p.is_file()}


def _stop_after_cancel(cluster, run: subprocess.Popen, job_id: str, grace=10) -> str:
    """snakemake's output once the cancelled job's run has ended. snakemake-executor-plugin-slurm
    2.8.0 knows the state CANCELLED, but sacct reports a job a user cancelled as "CANCELLED by
    <uid>" (SLURM 22.05 and later), which the plugin takes for a job still running: it waits for
    ever. So, as a user would, press Ctrl-C once sacct has the job cancelled and a status check
    or two have passed (docs/cluster.md, "Step by step")."""
    deadline = None
    while run.poll() is None:
        state = cluster.run("sacct", "-X", "-n", "-P", "-j", job_id, "-o", "State").strip()
        if state.startswith("CANCELLED") and deadline is None:
            deadline = time.monotonic() + grace
        if deadline is not None and time.monotonic() > deadline:
            run.send_signal(signal.SIGINT)
            break
        time.sleep(1)
    return _finish(run, timeout=300)


def test_workflow_on_slurm(slurm_cluster, tmp_path, children):
    cluster = slurm_cluster
    cluster_dir, local_dir = tmp_path / "cluster", tmp_path / "local"
    # The local run of the same config, beside the cluster's: its outputs are the reference.
    local = _popen(cluster, _command(local_dir, "--workflow-profile", LOCAL_PROFILE, *TARGETS), children)

    # 1. Through SLURM; the crops' group job is cancelled mid-run with scancel.
    before = last_job_id(cluster)
    run = _popen(cluster, _command(cluster_dir, *_slurm_args(*TARGETS)), children)
    group_id = _wait_for_running_group(cluster, cluster_dir / "results/boxes/logs/duplicates_crop", run)
    cluster.run("scancel", group_id)
    first = _stop_after_cancel(cluster, run, group_id)
    assert run.returncode != 0, first[-4000:]
    jobs = sacct_jobs(cluster, before)
    assert_all_through_slurm(first, jobs)
    states = {job_rule(job): job["State"] for job in jobs}
    assert states == {
        "synthesize": "COMPLETED",
        "cameras": "COMPLETED",
        "segment": "COMPLETED",
        f"{GROUP}_duplicates_crop": states.get(f"{GROUP}_duplicates_crop"),
    }, states
    assert states[f"{GROUP}_duplicates_crop"].startswith("CANCELLED"), states
    # A crop that finished before the cancel is kept; the others left nothing under their names.
    done = [i for i in INSTANCES if all((cluster_dir / t).exists() for t in _crop_files(i))]
    rest = [i for i in INSTANCES if i not in done]
    assert rest, "every crop had finished before the cancel: it was not mid-run"
    assert not any((cluster_dir / t).exists() for i in rest for t in _crop_files(i)), "a cancelled crop left output"
    assert_requests(jobs, crops=len(INSTANCES))
    stages = ("capture", "cameras", "segmentation")
    finished = {d: _mtimes(cluster_dir / "results/boxes" / d) for d in stages}
    finished["crops"] = {t: (cluster_dir / t).stat().st_mtime_ns for i in done for t in _crop_files(i)}

    # 2. The next invocation re-runs the cancelled crops, and only them.
    before = last_job_id(cluster)
    second = _run(cluster, _command(cluster_dir, *_slurm_args(*TARGETS)), children)
    assert second.returncode == 0, second.stdout[-4000:]
    assert announced_jobs(second.stdout) == {"local": {}, "remote": {"duplicates_crop": len(rest)}}
    jobs = sacct_jobs(cluster, before)
    assert_all_through_slurm(second.stdout, jobs)
    assert [job["State"] for job in jobs] == ["COMPLETED"], jobs
    assert_requests(jobs, crops=len(rest))
    again = {d: _mtimes(cluster_dir / "results/boxes" / d) for d in stages}
    again["crops"] = {t: (cluster_dir / t).stat().st_mtime_ns for t in finished["crops"]}
    assert again == finished, "finished jobs were redone"

    # 3. The outputs equal the local run's.
    local_out = _finish(local)
    assert local.returncode == 0, local_out[-4000:]
    assert announced_jobs(local_out)["remote"] == {}, "the local run handed jobs to an executor"
    # Every stage up to the crops is deterministic at a fixed seed (order-independent
    # accumulation; numpy's npz carries no write time): the same files, byte for byte.
    cluster_files = _outputs(cluster_dir)
    assert cluster_files == _outputs(local_dir)
    assert {Path(name).parts[0] for name in cluster_files} == {"capture", "cameras", "segmentation", "crops"}
    for name in cluster_files:
        cluster_bytes = (cluster_dir / "results/boxes" / name).read_bytes()
        assert cluster_bytes == (local_dir / "results/boxes" / name).read_bytes(), name

    # 4. A job that fails (its input made unreadable) names its logs in snakemake's message.
    image = cluster_dir / "results/boxes/capture/images/view_000.exr"
    image.write_bytes(b"not an EXR file")
    before = last_job_id(cluster)
    failed = _run(cluster, _command(cluster_dir, *_slurm_args("--forcerun", "segment", *TARGETS)), children)
    assert failed.returncode != 0, failed.stdout[-4000:]
    (job,) = sacct_jobs(cluster, before)
    assert (job_rule(job), job["State"]) == ("segment", "FAILED"), job
    slurm_log = f"{cluster_dir}/.snakemake/slurm_logs/rule_segment/boxes/{job['JobID']}.log"
    message = re.search(r"(?ms)^Error in rule segment:\n.*?^    log: (.*)$", failed.stdout)
    assert message, failed.stdout[-4000:]
    assert message.group(1).startswith(f"results/boxes/logs/segment.log, {slurm_log}"), message.group(0)
    assert "view_000.exr" in (cluster_dir / "results/boxes/logs/segment.log").read_text()

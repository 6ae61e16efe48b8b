"""The device check: a device whose runtime cannot build the kernels is skipped with one line that
names it and its compiler's message, and with none left a stage exits 2 saying what to install.

A device is made to fail for real, through its runtime's own compiler settings: PoCL takes extra
build flags from POCL_EXTRA_BUILD_FLAGS (an unknown -mcpu fails every build, as PyPI's PoCL 3.0
does on CPUs its LLVM does not know), Intel's runtime its target from CL_CONFIG_CPU_TARGET_ARCH
(an unknown one leaves the device unavailable)."""

import os
import subprocess
import sys

import pyopencl as cl
import pytest

from invrender.render import device as dev

BREAK = {  # a platform name's substring -> the setting that stops its runtime building kernels
    "Portable Computing Language": ("POCL_EXTRA_BUILD_FLAGS", "-mcpu=generic"),
    "Intel(R) OpenCL": ("CL_CONFIG_CPU_TARGET_ARCH", "generic"),
}
EXPECTED_MESSAGE = {
    "Portable Computing Language": "Invalid build option: -mcpu=generic",
    "Intel(R) OpenCL": "DEVICE_NOT_AVAILABLE",
}


def runtime_of(name: str) -> str:
    return next(platform for platform in BREAK if name.startswith(platform))


def invrender(*args, env_extra: dict, cache) -> subprocess.CompletedProcess:
    env = os.environ | {"INVRENDER_CACHE": str(cache), "PYOPENCL_NO_CACHE": "1"} | env_extra
    env.pop("INVRENDER_DEVICE", None)
    return subprocess.run(
        [sys.executable, "-m", "invrender.cli", *args], capture_output=True, text=True, env=env, timeout=600
    )


def chosen(run: subprocess.CompletedProcess) -> str:
    (line,) = [line for line in run.stdout.splitlines() if line.startswith("a run uses ")]
    return line.removeprefix("a run uses ").split(": ")[0]


def test_a_device_that_cannot_build_is_skipped_with_its_compilers_message(tmp_path):
    """The device a run would use, broken, gives way to the next runtime in rank order; the one
    line of the log names it and what its compiler said, and so does the survey. (The README's
    set-up installs two CPU runtimes, Intel's and the PoCL bundled with pyopencl.)"""
    preferred = dev.describe(dev.choose_device(None))
    runtime = runtime_of(preferred)
    peers = [d for d in dev.all_devices() if not dev.describe(d).startswith(runtime)]
    assert peers, "one runtime only"
    if all(dev.kernel_check(d) is not None for d in peers):
        # No second runtime builds here (PyPI's PoCL on a CPU its LLVM does not know): that one
        # is the broken device, ranked below the preferred; the survey says so with its message
        _the_survey_names_a_runtime_that_cannot_build(peers, preferred, tmp_path)
        return
    variable, value = BREAK[runtime]
    broken = invrender("devices", "--no-throughput", env_extra={variable: value}, cache=tmp_path / "b")
    assert broken.returncode == 0, broken.stderr
    assert runtime_of(chosen(broken)) != runtime
    (row,) = [line for line in broken.stdout.splitlines() if f" {preferred} " in line]
    assert "  no: " in row and EXPECTED_MESSAGE[runtime] in row
    (config := tmp_path / "small.yaml").write_text("cameras: {count: 1, width: 8, height: 6}\n")
    stage = invrender(
        "synthesize",
        "room",
        "--out",
        str(tmp_path / "capture"),
        "--config",
        str(config),
        "--spp",
        "1",
        env_extra={variable: value},
        cache=tmp_path / "b",
    )
    assert stage.returncode == 0, stage.stderr
    (skipped,) = [line for line in stage.stderr.splitlines() if " WARNING " in line]
    assert f"skipping {preferred}" in skipped and EXPECTED_MESSAGE[runtime] in skipped


def _the_survey_names_a_runtime_that_cannot_build(broken: list, preferred: str, tmp_path) -> None:
    survey = invrender("devices", "--no-throughput", env_extra={}, cache=tmp_path / "n")
    assert survey.returncode == 0, survey.stderr
    assert chosen(survey) == preferred
    for device in broken:
        (row,) = [line for line in survey.stdout.splitlines() if f" {dev.describe(device)} " in line]
        assert "  no: " in row and dev.kernel_check(device).split(": ")[-1] in row


def test_with_no_device_that_builds_a_stage_exits_2_naming_what_to_install(tmp_path):
    everything_broken = dict(BREAK.values())
    out = tmp_path / "capture"
    run = invrender(
        "synthesize", "room", "--out", str(out), "--spp", "1", env_extra=everything_broken, cache=tmp_path / "c"
    )
    assert run.returncode == 2, run.stderr
    errors = [line for line in run.stderr.splitlines() if " ERROR " in line]
    assert len(errors) == 1 and "builds the kernels" in errors[0] and "pip install intel-opencl-rt" in errors[0]
    for device in dev.all_devices():
        assert dev.describe(device) in errors[0]
    assert not out.exists() and not list(tmp_path.glob("capture*"))


def test_a_device_name_that_matches_nothing_exits_2(tmp_path):
    run = invrender("devices", "--no-throughput", "--device", "NoSuchGPU", env_extra={}, cache=tmp_path)
    assert run.returncode == 2
    assert "no OpenCL device matches 'NoSuchGPU'; available: " in run.stderr


def test_the_verdict_is_cached_and_a_new_kernel_source_checks_again(tmp_path, monkeypatch):
    monkeypatch.setenv("INVRENDER_CACHE", str(tmp_path))
    device = dev.all_devices()[0]
    builds = []
    monkeypatch.setattr(dev, "_build_entry_kernels", lambda d: builds.append(d) or "error: made up")
    assert dev.kernel_check(device) == "error: made up"
    assert dev.kernel_check(device) == "error: made up" and len(builds) == 1
    real_entries = dev.entry_kernels
    monkeypatch.setattr(dev, "entry_kernels", lambda d: real_entries(d) + [("probe.cl", ())])
    assert dev.kernel_check(device) == "error: made up" and len(builds) == 2


def test_rank_puts_gpus_first_then_the_cpu_runtimes_in_measured_order():
    class Fake:
        def __init__(self, platform, version, kind=cl.device_type.CPU):
            self.platform = type("Platform", (), {"name": platform, "version": version})()
            self.type = kind

    pypi = Fake("Portable Computing Language", "OpenCL 3.0 PoCL 3.0-rc2  Linux")
    debian = Fake("Portable Computing Language", "OpenCL 3.0 PoCL 3.1+debian  Linux")
    intel = Fake("Intel(R) OpenCL", "OpenCL 3.1 LINUX")
    nvidia = Fake("NVIDIA CUDA", "OpenCL 3.0 CUDA 12.4.131", cl.device_type.GPU)
    other = Fake("Some CPU runtime", "OpenCL 1.2")
    by_rank = sorted([other, pypi, debian, intel, nvidia], key=dev.rank)
    cpus = [f for name in dev.CPU_RUNTIMES for f in (intel, debian, pypi) if f.platform.name == name]
    assert by_rank == [nvidia, *cpus, other]


@pytest.mark.parametrize(
    "text, expected",
    [
        (
            "clBuildProgram failed: BUILD_PROGRAM_FAILURE - clBuildProgram failed: BUILD_PROGRAM_FAILURE\n\n"
            "Build on <pyopencl.Device 'pthread-AMD EPYC'>:\n\nerror: unknown target CPU 'generic'\n"
            "note: valid target CPU values are: nocona, core2\n\n(options: -I /x)",
            "clBuildProgram failed: BUILD_PROGRAM_FAILURE: error: unknown target CPU 'generic'",
        ),
        ("Context failed: DEVICE_NOT_AVAILABLE", "Context failed: DEVICE_NOT_AVAILABLE"),
    ],
)
def test_the_compilers_message_is_one_line(text, expected):
    assert dev.compiler_message(RuntimeError(text)) == expected


def test_pymeshlab_imported_first_does_not_hide_intels_runtime():
    """pymeshlab bundles an older libtbb.so.12, with which Intel's runtime fails to load; the
    package loads the newer one first (render/runtimes.py)."""
    code = "import invrender, pymeshlab\nfrom invrender.render.device import all_devices, describe\n"
    code += "print([describe(d) for d in all_devices()])"
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert "Intel(R) OpenCL" in run.stdout, run.stdout + run.stderr

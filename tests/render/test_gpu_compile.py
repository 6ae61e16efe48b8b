"""GPU readiness without a GPU: every kernel build the host makes compiles, as portable OpenCL C
1.2, for an AMD (amdgcn, gfx90a) and an NVIDIA (nvptx64) target with Debian's clang-19 (README's
"Set up" installs it), down to GPU assembly (-S), so the back ends see the code too. The source is
what the host builds (program.assemble_source) with the options it passes (Features.defines(),
adjoint.LAYOUT_DEFINES and accumulation_defines).

Builds: feature sets made from Features' boolean fields (so a flag added there is covered
without touching this file): all on, all off, and each on alone (with the fewest others it needs:
window and env_sampling need environment), times render.cl, probe.cl and adjoint.cl in both
accumulation modes; plus render.cl with the FIXED_PROPOSAL test hook and all effects built as for
a device without fp64 (the float32 watertight path, which PoCL, amdgcn and nvptx would all skip).
On nvptx64 the fixed-point adjoint is built with cl_khr_int64_base_atomics declared, as NVIDIA's
driver reports it and clang's nvptx target does not; the buckets adjoint is built without it, which
proves that mode never needs it. Without it, the fixed mode fails on the kernel's own #error.
90 clang runs, on every core; the 64 of the "alone" sets stop after the front end (see back_end):
17 s of CPU in all (42 s when all went down to assembly).

Also here: the host's choice of accumulation mode from a device's extensions (a fake device).
"""

import logging
import os
import shutil
import subprocess
from concurrent.futures import ThreadPoolExecutor
from dataclasses import fields, replace
from types import SimpleNamespace

import numpy as np
import pytest
from testscenes import box_room

from invrender.render import adjoint
from invrender.render.adjoint import LAYOUT_DEFINES, NUM_BUCKETS, accumulation_defines, backward, choose_accumulation
from invrender.render.device import DeviceError
from invrender.render.features import Features
from invrender.render.program import assemble_source
from invrender.render.renderer import Renderer, pixel_requests

CLANG = "clang-19"
LANGUAGE = ("-x", "cl", "-cl-std=CL1.2", "-Xclang", "-finclude-default-header")
TARGETS = {
    # without -nogpulib clang asks for ROCm's device library, which a compile check does not need
    "amdgcn": ("-target", "amdgcn-amd-amdhsa", "-mcpu=gfx90a", "-nogpulib"),
    "nvptx64": ("-target", "nvptx64-nvidia-nvcl"),
}
INT64_ATOMICS = ("-Xclang", "-cl-ext=+cl_khr_int64_base_atomics")  # what NVIDIA's driver declares
NO_FP64 = ("-Xclang", "-cl-ext=-cl_khr_fp64")  # a device without doubles (many Intel and ARM GPUs)
FLAGS = [f.name for f in fields(Features) if f.type in (bool, "bool")]


def clang(entry: str, options: tuple[str, ...], target: str, extra: tuple[str, ...] = (), assemble: bool = True):
    if shutil.which(CLANG) is None:
        pytest.fail(f"{CLANG} not found: README.md's 'Set up' installs it (apt-get install -y clang-19)")
    # The host passes "-D NAME=value" as one option; clang wants "-D" and "NAME=value" apart.
    defines = [word for option in options for word in option.split()]
    output = ("-S", "-o", os.devnull) if assemble else ("-fsyntax-only",)
    command = [CLANG, *LANGUAGE, *TARGETS[target], *extra, *defines, *output, "-"]
    return subprocess.run(command, input=assemble_source(entry), capture_output=True, text=True)


def alone(flag: str) -> Features:
    """`flag` on, with the fewest other flags a valid Features needs (window needs environment)."""
    for others in [(), *((other,) for other in FLAGS if other != flag)]:
        try:
            return Features.only(max_bounces=1, **dict.fromkeys((flag, *others), True))
        except ValueError:
            continue
    raise AssertionError(f"Features: no valid set with only {flag} and one other flag on")


def feature_sets() -> dict[str, Features]:
    sets = {"all on": replace(Features.everything(), roulette_depth=3), "all off": Features.only()}
    return sets | {f"{flag} alone": alone(flag) for flag in FLAGS}


def builds(target: str) -> list[tuple[str, str, tuple[str, ...], tuple[str, ...]]]:
    """(name, entry, host options, target-specific clang options) of every build for `target`."""
    # The back end compiles constructs, not combinations: every #if block's code is in "all on" or
    # "all off", which go down to assembly (see back_end); the "alone" sets add combinations, whose
    # failures (a name declared only under another flag, a type mismatch) are the front end's.
    fixed_extra = INT64_ATOMICS if target == "nvptx64" else ()
    out = []
    for name, features in feature_sets().items():
        defines = features.defines()
        adjoint_defines = defines + LAYOUT_DEFINES  # as adjoint._accumulate passes them
        out += [
            (f"render.cl, {name}", "render.cl", defines, ()),
            (f"probe.cl, {name}", "probe.cl", defines, ()),
            (f"adjoint.cl fixed, {name}", "adjoint.cl", adjoint_defines + accumulation_defines(None), fixed_extra),
            (f"adjoint.cl buckets, {name}", "adjoint.cl", adjoint_defines + accumulation_defines(NUM_BUCKETS), ()),
        ]
    everything = Features.everything().defines()
    out.append(("render.cl FIXED_PROPOSAL, all on", "render.cl", everything + ("-D FIXED_PROPOSAL",), ()))
    out += [(f"{name}, without fp64", entry, options, extra + NO_FP64) for name, entry, options, extra in out[:4]]
    return out


def test_every_features_field_is_a_flag_or_the_bounce_count():
    """The builds below enumerate boolean flags; a field of another kind needs its values named here
    (roulette_depth: on in "all on", off elsewhere; w_env and w_emit are kernel arguments, not
    build options)."""
    assert {f.name for f in fields(Features)} - set(FLAGS) == {"max_bounces", "roulette_depth", "w_env", "w_emit"}
    assert len(feature_sets()) == len(FLAGS) + 2
    assert all(getattr(alone(flag), flag) for flag in FLAGS)


def back_end(name: str) -> bool:
    """Whether build `name` goes down to GPU assembly (-S) or stops after the front end
    (-fsyntax-only: parsing, names, types; a tenth of the time). Down to assembly: all on, all off,
    FIXED_PROPOSAL and the builds without fp64, so each target's back end sees every construct of
    every kernel file; the "alone" sets, 32 of the 45 builds, add only combinations."""
    return not name.endswith(" alone")


def test_the_back_end_sees_every_kernel_file_in_all_on_and_all_off():
    for target in TARGETS:
        deep = {(entry, name.split(", ")[-1]) for name, entry, *_ in builds(target) if back_end(name)}
        assert {
            (entry, which) for entry in ("render.cl", "probe.cl", "adjoint.cl") for which in ("all on", "all off")
        } <= deep
        assert sum(not back_end(name) for name, *_ in builds(target)) == 4 * len(FLAGS)


@pytest.mark.parametrize("target", list(TARGETS))
def test_every_kernel_build_compiles_for_gpu_targets(target):
    cases = builds(target)
    with ThreadPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        results = list(pool.map(lambda case: clang(case[1], case[2], target, case[3], back_end(case[0])), cases))
    failed = [f"{case[0]}:\n{result.stderr[-1500:]}" for case, result in zip(cases, results) if result.returncode]
    assert not failed, f"{len(failed)} of {len(cases)} builds fail for {target}:\n" + "\n".join(failed)
    # Portable means no extension the target lacks: clang warns on such a pragma and goes on.
    ignored = [case[0] for case, result in zip(cases, results) if "unsupported OpenCL extension" in result.stderr]
    assert not ignored, f"builds that enable an extension {target} does not declare: {ignored}"


def test_fixed_point_without_int64_atomics_fails_on_the_kernels_own_error():
    """clang's nvptx64 target, as it comes, lacks cl_khr_int64_base_atomics: the fixed-point build
    stops at adjoint.cl's #error naming the extension and the way out (the host never gets there:
    choose_accumulation picks buckets), instead of at an ambiguous atom_add."""
    options = Features.everything().defines() + LAYOUT_DEFINES + accumulation_defines(None)
    result = clang("adjoint.cl", options, "nvptx64")
    assert result.returncode != 0
    first_error = next(line for line in result.stderr.splitlines() if "error:" in line)
    assert "needs cl_khr_int64_base_atomics" in first_error and "ACCUMULATE_BUCKETS" in first_error, result.stderr


def fake_device(extensions: str) -> SimpleNamespace:
    return SimpleNamespace(extensions=extensions, name="Fake GPU", platform=SimpleNamespace(name="Fake platform"))


WITH = "cl_khr_fp64  cl_khr_int64_base_atomics cl_khr_int64_extended_atomics"  # drivers pad with spaces
WITHOUT = "cl_khr_fp64 cl_khr_global_int32_base_atomics cl_khr_int64_extended_atomics"


def test_auto_accumulation_follows_the_devices_int64_atomics(caplog):
    adjoint._told_buckets.clear()
    with caplog.at_level(logging.INFO, logger="invrender.render.adjoint"):
        assert choose_accumulation(fake_device(WITH)) == "fixed"
        assert not caplog.records
        assert [choose_accumulation(fake_device(WITHOUT), "auto") for _ in range(3)] == ["buckets"] * 3
    (record,) = caplog.records  # one line per device, not per call
    assert "Fake platform / Fake GPU" in record.getMessage() and "cl_khr_int64_base_atomics" in record.getMessage()


def test_explicit_modes_are_kept_and_fixed_without_int64_atomics_is_an_error():
    assert choose_accumulation(fake_device(WITH), "buckets") == "buckets"
    assert choose_accumulation(fake_device(WITHOUT), "buckets") == "buckets"
    assert choose_accumulation(fake_device(WITH), "fixed") == "fixed"
    with pytest.raises(DeviceError, match="'fixed' needs 64-bit integer atomics.*Fake GPU"):
        choose_accumulation(fake_device(WITHOUT), "fixed")
    with pytest.raises(ValueError, match="accumulation"):
        choose_accumulation(fake_device(WITH), "float")


def test_backward_on_a_device_without_int64_atomics_runs_buckets(monkeypatch, caplog):
    """PoCL reports the extension, so auto is fixed point here (bitwise repeatable); with the
    extension's name changed to one no device has, the same call runs buckets (not bitwise
    repeatable, equal to fixed point within float rounding) and 'fixed' is refused."""
    scene = box_room(window=True, ks=0.3, ka=0.05, light=8.0, sky=2.0)
    camera = scene.cameras[0]
    requests = pixel_requests(camera)[::7]
    adjoint_radiance = np.random.default_rng(0).uniform(0.5, 1.5, (len(requests), 3)).astype(np.float32)
    renderer = Renderer(scene, Features.everything(max_bounces=2))
    run = lambda accumulation: backward(renderer, [camera], requests, adjoint_radiance, 4, 3, accumulation)  # noqa: E731
    fixed, again = run("auto"), run("fixed")
    assert all(fixed[name].tobytes() == again[name].tobytes() for name in fixed)
    monkeypatch.setattr(adjoint, "INT64_ATOMICS", "cl_khr_int64_base_atomics_absent")
    adjoint._told_buckets.clear()
    built = []  # the accumulation of each adjoint.cl build: None is fixed point, else the bucket count
    monkeypatch.setattr(adjoint, "accumulation_defines", lambda b: built.append(b) or accumulation_defines(b))
    with caplog.at_level(logging.INFO, logger="invrender.render.adjoint"):
        buckets = run("auto")
    assert built == [NUM_BUCKETS]
    assert any("float buckets" in record.getMessage() for record in caplog.records)
    for name in fixed:
        scale = np.abs(fixed[name]).max()
        assert scale > 0, name
        np.testing.assert_allclose(buckets[name], fixed[name], rtol=0, atol=2e-4 * scale, err_msg=name)
    with pytest.raises(DeviceError, match="fixed"):
        run("fixed")

"""Shared by all tests: the helper modules under tests/ import by name, and kernel builds go to
a cache private to the test session unless INVRENDER_CACHE says otherwise."""

import sys
from pathlib import Path

import pytest

# drjit's LLVM backend reads DRJIT_LIBLLVM_PATH: point it at a usable libLLVM
# (invrender/mitsuba/llvm.py) before any test module imports drjit or mitsuba, in any order.
import invrender.mitsuba.llvm  # noqa: E402, F401

HERE = Path(__file__).parent
HELPER_DIRS = (
    "render",
    "geometry",
    "import_",
    "fuzz",
    "milo",
    "duplicates",
    "duplicates_material",
    "materials",
    "room_box",
    "room_objects",
)
HELPER_DIRS += ("room_materials", "bench")
for helper_dir in (HERE, *(HERE / name for name in HELPER_DIRS)):
    if str(helper_dir) not in sys.path:
        sys.path.insert(0, str(helper_dir))


@pytest.fixture(scope="module")
def stage_scene_dir(tmp_path_factory):
    """A scene directory on disk, as a stage reads it: the box room with a window and a glossy
    lobe (every feature the analysis can switch), its camera's image named view.exr."""
    from testscenes import box_room

    from invrender.scene.format import write_scene

    path = tmp_path_factory.mktemp("stage") / "scene"
    scene = box_room(window=True, ks=0.3, ka=0.05)
    scene.cameras[0].name = "view.exr"
    write_scene(path, scene)
    return path


# The fast tier, `pytest -n 2 -m fast`: every stage's unit tests on tiny fixtures, in under three
# minutes on two cores, needing none of SLURM, Chromium or Blender; contributors run it while they
# work, CI runs the whole suite. A test is in it unless its file is in FULL_SUITE_ONLY (whole
# workflow runs and dry runs, the SLURM cluster, Blender, Mitsuba's bridge, the benchmarks'
# harnesses, fuzzing, the CLI in processes of its own) or tests/slow_tests.txt lists it for its
# time (tests/tiers.py makes that list from a --durations run).
FULL_SUITE_ONLY = (
    "workflow/",
    "cluster/",
    "fuzz/",
    "bench/",
    "mitsuba/",
    "export/test_export_blender.py",
    "test_cli_signals.py",
    "test_cli_outputs.py",
)
SLOW_TESTS = HERE / "slow_tests.txt"


def pytest_collection_modifyitems(config, items):
    listed = {line.strip() for line in SLOW_TESTS.read_text().splitlines() if line.strip() and line[0] != "#"}
    for item in items:
        path = Path(str(item.fspath)).resolve().relative_to(HERE).as_posix()
        if item.nodeid in listed:
            item.add_marker(pytest.mark.slow)
        if (
            not item.get_closest_marker("slow")
            and not item.get_closest_marker("benchmark")
            and not path.startswith(FULL_SUITE_ONLY)
        ):
            item.add_marker(pytest.mark.fast)

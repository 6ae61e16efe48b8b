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
HELPER_DIRS += ("room_materials",)
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

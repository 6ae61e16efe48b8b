"""The two demo scenes (the room of the multiview mode, the cans of the duplicates mode) as scene
directories and their USD exports, built once per session: both take about a second."""

import pytest

from invrender.export import export_usd
from invrender.scene.format import write_scene
from invrender.synthesize import make_duplicates, make_room


@pytest.fixture(scope="session")
def demo_dirs(tmp_path_factory):
    root = tmp_path_factory.mktemp("demo")
    dirs = {}
    for name, make in (("room", make_room), ("cans", make_duplicates)):
        scene, metadata = make({})
        write_scene(root / name, scene, metadata)
        dirs[name] = root / name
    return dirs


@pytest.fixture(scope="session")
def demo_exports(demo_dirs, tmp_path_factory):
    root = tmp_path_factory.mktemp("exports")
    return {name: export_usd(path, root / name, usdc=True) and root / name for name, path in demo_dirs.items()}

import pytest
from milo_capture import WINDOW_ROOM, build_capture


@pytest.fixture(scope="module")
def tiny_capture(tmp_path_factory):
    return build_capture(tmp_path_factory.mktemp("milo"))


@pytest.fixture(scope="session")
def window_room(tmp_path_factory):
    """The benchmark's room and views with the sun through its window, rendered by our kernels."""
    return build_capture(tmp_path_factory.mktemp("window_room"), WINDOW_ROOM, spp=16)

import pytest
from milo_capture import build_capture


@pytest.fixture(scope="module")
def tiny_capture(tmp_path_factory):
    return build_capture(tmp_path_factory.mktemp("milo"))

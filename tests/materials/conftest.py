"""The materials' tests run torch on one thread (their tensors are small; base.single_thread
says why), restoring the count after each test."""

import pytest
import torch


@pytest.fixture(autouse=True)
def one_thread():
    saved = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(saved)

import pytest
import torch

from flownav.flows import GridFlow
from flownav.flows.synthetic import synthetic_wake

torch.set_num_threads(1)


@pytest.fixture(scope="session")
def wake_like_flow() -> GridFlow:
    """A smooth, unsteady grid flow on the wake's box with its cylinder (for tests that need a 'real' flow)."""
    return synthetic_wake()

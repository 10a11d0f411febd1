
import numpy as np
import pytest
from hypothesis import settings

# Hypothesis: no per-example deadline (the first example may trigger numba compilation).
settings.register_profile("lockgraph", deadline=None, max_examples=40, derandomize=True)
settings.load_profile("lockgraph")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)

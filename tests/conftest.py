import importlib.util
from pathlib import Path

import numpy as np
import pytest
from hypothesis import settings

# Hypothesis: no per-example deadline (the first example may trigger numba compilation).
settings.register_profile("lockgraph", deadline=None, max_examples=40, derandomize=True)
settings.load_profile("lockgraph")


@pytest.fixture
def rng():
    return np.random.default_rng(12345)


BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


@pytest.fixture(scope="session")
def load_benchmark():
    """``load_benchmark(name)``: ``benchmarks/<name>.py`` as a module, loaded as
    when it runs as a script (its folder on the path while it loads, for
    ``host_probe`` and the like)."""
    def load(name):
        with pytest.MonkeyPatch.context() as mp:
            mp.syspath_prepend(str(BENCHMARKS))
            spec = importlib.util.spec_from_file_location(f"{name}_under_test",
                                                          BENCHMARKS / f"{name}.py")
            mod = importlib.util.module_from_spec(spec)
            spec.loader.exec_module(mod)
        return mod
    return load

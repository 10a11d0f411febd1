"""State round trips: .npz files and ase.Atoms, bit for bit."""
import numpy as np

from lockgraph import scenarios
from lockgraph.state import State


def assert_same(a, b):
    for name in ("pos", "vel", "radius", "mass", "t_local", "ncoll", "t_last"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert a.time == b.time


def evolved():
    sc = scenarios.load("dish", n=60, params={"cylinder_radius": 0.004, "dt": 0.001})
    sim = sc.simulation()
    sim.run(40)
    return sim.state, sc.physics


def test_npz_round_trip(tmp_path):
    st, _ = evolved()
    path = tmp_path / "s.npz"
    st.save(path)
    back = State.load(path)
    assert_same(st, back)
    assert back.sha256() == st.sha256()
    with np.load(path) as f:
        assert {"pos", "vel", "radius", "mass"} <= set(f.files)


def test_ase_round_trip():
    st, ph = evolved()
    atoms = st.to_ase(ph.domain)
    assert len(atoms) == st.n
    assert np.array_equal(atoms.get_masses(), st.mass)
    assert np.array_equal(atoms.arrays["radius"], st.radius)
    back = State.from_ase(atoms)
    assert_same(st, back)


def test_save_is_atomic(tmp_path, monkeypatch):
    """A write that fails half way leaves the previous file untouched."""
    st, _ = evolved()
    path = tmp_path / "s.npz"
    st.save(path)
    before = path.read_bytes()

    def boom(*a, **k):
        raise OSError("disk full")

    monkeypatch.setattr(np, "savez", boom)
    try:
        st.save(path)
    except OSError:
        pass
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == ["s.npz"]


def test_sha256_is_of_pos_then_vel():
    import hashlib
    st, _ = evolved()
    h = hashlib.sha256(st.pos.tobytes() + st.vel.tobytes()).hexdigest()
    assert st.sha256() == h


def test_kernel_cache_is_keyed_by_the_numba_modules_sources(tmp_path):
    """Compiled kernels are cached per version of every numba module's source:
    changing one kernel module moves all kernels to a fresh directory (numba
    alone would keep a caller's stale inlined copy); other modules do not."""
    import shutil

    from lockgraph import _jit, parallel

    assert _jit.KERNEL_CACHE.endswith(_jit.source_key())
    assert parallel.worker._cache._cache_path.startswith(_jit.KERNEL_CACHE)
    for p in _jit.HERE.glob("*.py"):
        shutil.copy(p, tmp_path / p.name)
    key = _jit.source_key(tmp_path)
    assert key == _jit.source_key()
    cli = tmp_path / "cli.py"
    cli.write_text(cli.read_text() + "\n# a comment\n")
    assert _jit.source_key(tmp_path) == key  # no numba in it
    k = tmp_path / "kernels.py"
    k.write_text(k.read_text() + "\n# a comment\n")
    assert _jit.source_key(tmp_path) != key


RACE = """
import sys
from lockgraph import _jit
from numba.core import caching
f = caching.IndexDataCacheFile(sys.argv[1], "kernel", "stamp")
tag = sys.argv[2]
for k in range(60):
    f.save(tag + str(k), tag + str(k) * 2000)
"""


def test_kernel_cache_saves_do_not_race_across_processes(tmp_path):
    """Two processes saving different signatures of one kernel at once (the
    compile helper beside the main process, Dask workers) must not give two
    signatures one data file: every signature in the index loads its own
    data.  Without the lock around numba's save, three such processes lost
    or swapped 3 and 12 of 180 entries in two of three trials (and a cached
    kernel ran another signature's code in a fresh clone's tests)."""
    import os
    import subprocess
    import sys

    from numba.core import caching

    env = dict(os.environ, LOCKGRAPH_CACHE=str(tmp_path))
    env.pop("NUMBA_CACHE_DIR", None)  # it would replace the cache root given here
    path = tmp_path / "kernels" / "race"
    procs = [subprocess.Popen([sys.executable, "-c", RACE, str(path), tag], env=env)
             for tag in ("a", "b", "c")]
    assert [p.wait(timeout=120) for p in procs] == [0, 0, 0]
    f = caching.IndexDataCacheFile(str(path), "kernel", "stamp")
    for tag in "abc":
        for k in range(60):
            assert f.load(tag + str(k)) == tag + str(k) * 2000


def test_the_sessions_compile_leaves_every_helpers_kernels_on_disk():
    """``compile_kernels(pool=True)`` (the suites' session start) leaves the
    threaded worker and the pool's worker in numba's on-disk cache, which is
    what tells a later process (a test's child, a helper) to load rather
    than compile them."""
    from lockgraph.parallel import worker
    from lockgraph.pool import pool_worker
    from lockgraph.simulation import _on_disk, compile_kernels

    compile_kernels(pool=True)
    assert _on_disk(worker)
    assert _on_disk(pool_worker)


def test_compile_kernels_does_each_part_once_per_process(monkeypatch):
    """A part compiled or loaded once in this process (the session start's
    sequential, threaded and pool kernels) is not done again, whatever the
    arguments of a later call: a pool ``Simulation`` after a default one
    loaded every kernel a second time."""
    from lockgraph import simulation

    simulation.compile_kernels(pool=True)

    def again():
        raise AssertionError("a part was compiled or loaded again")

    for name in ("_compile_sequential", "_compile_threaded", "_compile_pool"):
        monkeypatch.setattr(simulation, name, again)
    base = simulation.compile_kernels()
    both = simulation.compile_kernels(pool=True)
    assert base == simulation._COMPILED["base"]
    assert both == base + simulation._COMPILED["pool"]

"""The one way lockgraph compiles numba kernels.

``kernel``: ``@njit(cache=True, nogil=True)`` without numba's reference-counted
runtime (NRT).  Kernels take plain numpy arrays, allocate nothing and return
status codes; without NRT, passing arrays between compiled functions costs no
atomic reference-count updates (measured on the event loop: 5.2 -> 1.4 us per
collision at N = 32,000).  ``inline=True`` also inlines the function into its
callers at numba-IR level (for the small, hot ones).

The compiled kernels are cached on disk in ``KERNEL_CACHE``, a directory named
for a hash of the sources of every module that uses numba.  Why: numba checks
a cached function against its own file's time stamp only, so a kernel that
inlines or calls a kernel of another module kept its old compiled body after
that module changed — measured: the threaded worker (``parallel.py``) cached
before the velocity guard was added to ``kernels.py`` ran without it.  Saves
into it are serialized across processes (``_locked``).
"""
import fcntl
import functools
import hashlib
import os
from pathlib import Path

from numba import njit
from numba.core import caching, config

HERE = Path(__file__).resolve().parent


def source_key(root=HERE):
    """sha256 (16 hex digits) of the modules in ``root`` (the package) that use numba."""
    h = hashlib.sha256()
    for p in sorted(Path(root).glob("*.py")):
        text = p.read_bytes()
        if p.name == "_jit.py" or b"numba" in text or b"_jit import" in text:
            h.update(p.name.encode() + b"\0" + text + b"\0")
    return h.hexdigest()[:16]


def _cache_root():
    # numba's own setting if the user made one, else lockgraph's cache
    if config.CACHE_DIR:
        return Path(config.CACHE_DIR)
    return Path(os.environ.get("LOCKGRAPH_CACHE", Path.home() / ".cache" / "lockgraph"))


KERNEL_CACHE = str(_cache_root() / "kernels" / source_key())
KERNEL_ROOT = os.path.dirname(KERNEL_CACHE)


def child_env(env=None):
    """The environment (default ``os.environ``) for a child process that should
    load this process's compiled kernels whatever ``LOCKGRAPH_CACHE`` it gets
    (numba's cache setting wins over it in ``_cache_root``).  Why: a suite
    moves LOCKGRAPH_CACHE to a private folder for states, and a child then
    compiled every kernel again (180 s on a clean clone)."""
    env = dict(os.environ if env is None else env)
    env.setdefault("NUMBA_CACHE_DIR", os.path.dirname(KERNEL_ROOT))
    return env


def _locked(save):
    """numba's ``IndexDataCacheFile.save`` under an exclusive file lock in the
    cache directory, for lockgraph's kernel caches.

    Why: ``save`` reads the function's index, picks the first free data-file
    number for a new signature, then writes index and data.  Two processes
    saving different signatures of one kernel at once (``compile_kernels``'s
    helper beside the main process, Dask workers, test subprocesses) both pick
    number 1: the index then names one signature's code for the other, and a
    call runs code compiled for other argument types (seen in a fresh clone:
    "can't unbox array from PyObject into native value" from a cached
    permutation kernel).  Under the lock the read, the pick and both writes
    are one step."""
    @functools.wraps(save)
    def wrapper(self, key, data):
        path = str(self._cache_path)
        if not path.startswith(KERNEL_ROOT):
            return save(self, key, data)
        os.makedirs(path, exist_ok=True)
        with open(os.path.join(path, "save.lock"), "a") as fh:
            fcntl.flock(fh, fcntl.LOCK_EX)
            try:
                return save(self, key, data)
            finally:
                fcntl.flock(fh, fcntl.LOCK_UN)
    wrapper.lockgraph_locked = True
    return wrapper


if not getattr(caching.IndexDataCacheFile.save, "lockgraph_locked", False):
    caching.IndexDataCacheFile.save = _locked(caching.IndexDataCacheFile.save)


def _njit(f, opts):
    # numba picks a function's cache directory when it is decorated: point it
    # at KERNEL_CACHE for lockgraph's kernels only, not for the process
    old = config.CACHE_DIR
    config.CACHE_DIR = KERNEL_CACHE
    try:
        return njit(**opts)(f)
    finally:
        config.CACHE_DIR = old


def kernel(fn=None, *, inline=False):
    opts = dict(cache=True, nogil=True, _nrt=False, error_model="numpy")
    if inline:
        opts["inline"] = "always"
    if fn is None:
        return lambda f: _njit(f, opts)
    return _njit(fn, opts)

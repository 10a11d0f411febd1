"""The atomic and cache-hint intrinsics (``lockgraph.atomics``): what each
compiles to on x86-64, and that the values they act on come out right."""
import platform

import numpy as np
import pytest
from numba import njit

from lockgraph.atomics import (cas, claim_from_ends, fetch_add, fetch_max, fetch_or, load,
                               prefetch_read, prefetch_write, store)

X86 = platform.machine() in ("x86_64", "AMD64")


@njit
def _hinted_sum(mat, vec, rows):
    """Sum of mat[r, 0] + vec[r] over rows, each row prefetched first (mat for
    writing, vec for reading)."""
    s = 0.0
    for r in rows:
        prefetch_write(mat, r)
        prefetch_read(vec, r)
        s += mat[r, 0] + vec[r]
    return s


@njit
def _rmw(a):
    old = fetch_add(a, 0, 5)
    fetch_max(a, 1, 7)
    seen = cas(a, 2, 3, 9)  # a[2] is 3: swapped
    miss = cas(a, 3, 0, 11)  # a[3] is 4: left
    store(a, 4, load(a, 0) + 1)
    was = fetch_or(a, 5, 12)  # 0b0101 | 0b1100
    return old, seen, miss, was


def _asm(fn):
    return fn.inspect_asm(fn.signatures[0])


class TestPrefetch:
    def test_values_unchanged(self):
        mat = np.arange(30.0).reshape(10, 3)
        vec = np.arange(10, dtype=np.int32)
        before = mat.copy(), vec.copy()
        rows = np.array([9, 0, 4, 4], np.int64)
        assert _hinted_sum(mat, vec, rows) == sum(mat[r, 0] + vec[r] for r in rows)
        assert np.array_equal(mat, before[0]) and np.array_equal(vec, before[1])

    @pytest.mark.skipif(not X86, reason="x86-64 instruction names")
    def test_compiles_to_prefetch_instructions(self):
        asm = _asm(_hinted_sum)
        assert "prefetchw" in asm  # for writing
        assert "prefetcht0" in asm  # for reading, into every cache level

    def test_rejects_a_scalar(self):
        @njit
        def bad(x):
            prefetch_read(x, 0)

        with pytest.raises(Exception, match="1-D or 2-D arrays"):
            bad(1.0)


class TestReadModifyWrite:
    def test_values(self):
        a = np.array([1, 2, 3, 4, 0, 5], np.int64)
        old, seen, miss, was = _rmw(a)
        assert (old, seen, miss, was) == (1, 3, 4, 5)
        assert a.tolist() == [6, 7, 9, 4, 7, 13]

    @pytest.mark.skipif(not X86, reason="x86-64 instruction names")
    def test_locked_instructions(self):
        # the measured fact: a CAS is one ``lock cmpxchg``
        asm = _asm(_rmw)
        assert "lock" in asm and "cmpxchg" in asm


@njit(nogil=True)
def _claims(claim, me, nthr, ntasks, out):
    """Thread me's claims (claim_from_ends) until none is left, into out;
    returns how many it took."""
    r = 0
    while True:
        q = claim_from_ends(claim, me, nthr, r, ntasks)
        if q >= ntasks:
            return r
        out[r] = q
        r += 1


@pytest.mark.parametrize("nthr", [1, 2, 3])
@pytest.mark.parametrize("ntasks", [1, 2, 7, 64, 5000])
def test_claims_from_the_ends_take_every_task_once(nthr, ntasks):
    """Every task is taken exactly once, by threads racing for them; on two
    threads the first's tasks are a run from the front in order and the
    second's a run from the back in reverse (so each thread's share is one
    run of slots), on one or three threads they are plain fetch-add claims."""
    import threading

    claim = np.zeros(8, np.int64)
    outs = [np.full(ntasks, -1, np.int64) for _ in range(nthr)]
    took = [0] * nthr

    def run(k):
        took[k] = _claims(claim, k, nthr, ntasks, outs[k])
    pool = [threading.Thread(target=run, args=(k,)) for k in range(nthr)]
    for th in pool:
        th.start()
    for th in pool:
        th.join()
    got = np.sort(np.concatenate([o[:t] for o, t in zip(outs, took)]))
    assert np.array_equal(got, np.arange(ntasks))
    if nthr == 2:
        assert np.array_equal(outs[0][:took[0]], np.arange(took[0]))
        assert np.array_equal(outs[1][:took[1]], np.arange(ntasks - 1, took[0] - 1, -1))


def test_claims_with_fixed_shares_deal_the_tasks_in_turn():
    """No claim word (``balance`` 0): task me + r nthr, nothing claimed."""
    out = np.full(10, -1, np.int64)
    assert _claims(np.zeros(0, np.int64), 1, 3, 10, out) == 3
    assert out[:3].tolist() == [1, 4, 7]

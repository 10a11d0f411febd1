"""The atomic and cache-hint intrinsics (``lockgraph.atomics``): what each
compiles to on x86-64, and that the values they act on come out right."""
import platform

import numpy as np
import pytest
from numba import njit

from lockgraph.atomics import (cas, fetch_add, fetch_max, fetch_or, load, prefetch_read,
                               prefetch_write, store)

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

"""Atomic operations on int32/int64 array elements for nogil kernels, and spin helpers.

numba has no CPU atomics; these ``@intrinsic`` functions emit LLVM's
``atomicrmw`` / ``cmpxchg`` / atomic ``load`` / ``store`` (sequentially
consistent) on the address of ``arr[i]``.  A thread that spins on memory another
thread writes must read it with ``load`` — a plain load in a loop is hoisted out
of the loop by LLVM and the thread never sees the change.

``prefetch_read`` / ``prefetch_write``: cache hints (LLVM's ``llvm.prefetch``)
for the lines an event is about to use; they change no value.

Float64 maxima: for non-negative doubles the IEEE bit patterns, read as signed
int64, order exactly like the values, so ``fetch_max`` on an int64 view of a
float64 array is an atomic maximum of non-negative floats.
"""
from llvmlite import ir
from numba import types
from numba.core import cgutils
from numba.extending import intrinsic

from ._jit import kernel


def _item_pointer(context, builder, arr_t, arr, idx_t, idx):
    """The address of arr[idx] (of row idx's first element, arr[idx, 0], for a
    2-D array)."""
    ary = context.make_array(arr_t)(context, builder, arr)
    i = context.cast(builder, idx, idx_t, types.intp)
    zero = context.get_constant(types.intp, 0)
    return cgutils.get_item_pointer(context, builder, arr_t, ary, [i] + [zero] * (arr_t.ndim - 1),
                                    wraparound=False)


def _check(arr):
    if not (isinstance(arr, types.Array) and arr.dtype in (types.int64, types.int32)
            and arr.ndim == 1):
        raise TypeError("atomics work on 1-D int32 or int64 arrays")


def _fetch(op, name, doc):
    """A read-modify-write intrinsic: LLVM's ``atomicrmw op`` (sequentially
    consistent) on arr[i] with val; it returns the old value."""
    def fetch(typingctx, arr, i, val):
        _check(arr)

        def codegen(context, builder, sig, args):
            ptr = _item_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1])
            v = context.cast(builder, args[2], sig.args[2], sig.args[0].dtype)
            return builder.atomic_rmw(op, ptr, v, "seq_cst")

        return arr.dtype(arr, i, val), codegen

    fetch.__name__ = name
    fetch.__doc__ = doc
    return intrinsic(fetch)


fetch_add = _fetch("add", "fetch_add", "arr[i] += val atomically; returns the old value.")
fetch_max = _fetch("max", "fetch_max",
                   "arr[i] = max(arr[i], val) atomically (signed); returns the old value.")
fetch_or = _fetch("or", "fetch_or", "arr[i] |= val atomically; returns the old value.")


@intrinsic
def cas(typingctx, arr, i, expected, new):
    """If arr[i] == expected store new; returns the value seen (== expected on success)."""
    _check(arr)

    def codegen(context, builder, sig, args):
        ptr = _item_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1])
        e = context.cast(builder, args[2], sig.args[2], sig.args[0].dtype)
        n = context.cast(builder, args[3], sig.args[3], sig.args[0].dtype)
        pair = builder.cmpxchg(ptr, e, n, "seq_cst", "seq_cst")
        return builder.extract_value(pair, 0)

    return arr.dtype(arr, i, expected, new), codegen


@intrinsic
def load(typingctx, arr, i):
    """Atomic (acquire) load of arr[i]: never hoisted out of a spin loop."""
    _check(arr)

    def codegen(context, builder, sig, args):
        ptr = _item_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1])
        return builder.load_atomic(ptr, "acquire", sig.args[0].dtype.bitwidth // 8)

    return arr.dtype(arr, i), codegen


@intrinsic
def store(typingctx, arr, i, val):
    """Atomic (release) store of val into arr[i]."""
    _check(arr)

    def codegen(context, builder, sig, args):
        ptr = _item_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1])
        v = context.cast(builder, args[2], sig.args[2], sig.args[0].dtype)
        builder.store_atomic(v, ptr, "release", sig.args[0].dtype.bitwidth // 8)
        return context.get_dummy_value()

    return types.none(arr, i, val), codegen


@intrinsic
def cpu_relax(typingctx):
    """The x86 PAUSE hint for spin loops (a no-op elsewhere)."""

    def codegen(context, builder, sig, args):
        fnty = ir.FunctionType(ir.VoidType(), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.x86.sse2.pause")
        builder.call(fn, [])
        return context.get_dummy_value()

    return types.none(), codegen


@intrinsic
def sched_yield(typingctx):
    """Give the CPU to another runnable thread (libc ``sched_yield``)."""

    def codegen(context, builder, sig, args):
        fnty = ir.FunctionType(ir.IntType(32), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "sched_yield")
        builder.call(fn, [])
        return context.get_dummy_value()

    return types.none(), codegen


@intrinsic
def sleep_us(typingctx, us):
    """Sleep ``us`` microseconds (libc ``usleep``): a long-blocked thread gives
    its core to the threads it waits for (when threads outnumber free cores)."""
    if not isinstance(us, types.Integer):
        raise TypeError("sleep_us takes an integer")

    def codegen(context, builder, sig, args):
        fnty = ir.FunctionType(ir.IntType(32), [ir.IntType(32)])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "usleep")
        builder.call(fn, [builder.trunc(args[0], ir.IntType(32))])
        return context.get_dummy_value()

    return types.none(us), codegen


@intrinsic
def float_bits(typingctx, x):
    """The IEEE-754 bits of a float64 as an int64 (a bit cast, no conversion)."""
    if x != types.float64:
        raise TypeError("float_bits takes a float64")

    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.IntType(64))

    return types.int64(x), codegen


@intrinsic
def bits_float(typingctx, x):
    """The float64 whose IEEE-754 bits are the int64 x (inverse of float_bits)."""
    if x != types.int64:
        raise TypeError("bits_float takes an int64")

    def codegen(context, builder, sig, args):
        return builder.bitcast(args[0], ir.DoubleType())

    return types.float64(x), codegen


@intrinsic
def cycles(typingctx):
    """The CPU's cycle counter (llvm.readcyclecounter): cheap timing inside kernels."""

    def codegen(context, builder, sig, args):
        fnty = ir.FunctionType(ir.IntType(64), [])
        fn = cgutils.get_or_insert_function(builder.module, fnty, "llvm.readcyclecounter")
        return builder.call(fn, [])

    return types.int64(), codegen


@kernel(inline=True)
def spin_lock(word, i):
    """Acquire the spinlock word[i] (0 free, 1 held): bounded spinning, then yielding."""
    spins = 0
    while True:
        if load(word, i) == 0 and cas(word, i, 0, 1) == 0:
            return
        spins += 1
        if spins < 64:
            cpu_relax()
        elif spins < 4096:
            sched_yield()
        else:
            sleep_us(20)  # the holder is likely descheduled: let it run


@kernel(inline=True)
def spin_unlock(word, i):
    store(word, i, 0)


@kernel(inline=True)
def next_task(claim, me, nthr, r):
    """Thread ``me`` of ``nthr``'s ``r``-th task (from 0) in a phase of
    claimed tasks: the next one by an atomic fetch-add on ``claim[0]`` (0 at
    the phase start), so a thread slowed down takes fewer; with ``claim``
    empty (fixed shares), task me + r nthr."""
    if claim.shape[0] > 0:
        return fetch_add(claim, 0, 1)
    return me + r * nthr


@kernel(inline=True)
def claim_from_ends(claim, me, nthr, r, ntasks):
    """``next_task`` over ``ntasks`` tasks in slot order, but with claims on
    two threads the first takes them from the front and the second from
    the back (its ``r``-th: ntasks - 1 - r).  ``ntasks`` or more: none left.
    The fetch-add counts the tasks both took, so the two ends never pass
    each other and each thread's share is one run of slots, the first
    thread's the lowest, as its run of the pool's domains
    (``pool.claim_masks``): what a thread writes in one phase it reads in
    the next from its own core's caches (``engine.py``: "Each thread its
    own end")."""
    k = next_task(claim, me, nthr, r)
    if claim.shape[0] == 0 or nthr != 2 or k >= ntasks:
        return k
    return r if me == 0 else ntasks - 1 - r


def _prefetch(rw, name, doc):
    """A ``prefetch`` intrinsic: LLVM's ``llvm.prefetch`` (rw 0: read, 1:
    write; locality 3: keep in every cache level) of the line holding row i of
    a 1-D or 2-D array of any type.  A hint only: it changes no value."""
    def prefetch(typingctx, arr, i):
        if not (isinstance(arr, types.Array) and arr.ndim in (1, 2)):
            raise TypeError("prefetch works on 1-D or 2-D arrays")

        def codegen(context, builder, sig, args):
            ptr = _item_pointer(context, builder, sig.args[0], args[0], sig.args[1], args[1])
            i8p = builder.bitcast(ptr, ir.IntType(8).as_pointer())
            i32 = ir.IntType(32)
            fnty = ir.FunctionType(ir.VoidType(), [i8p.type, i32, i32, i32])
            # the overload's name: ".p0" with opaque pointers (llvmlite >= 0.44),
            # ".p0i8" with typed ones
            opaque = getattr(i8p.type, "is_opaque", False)
            fn = cgutils.get_or_insert_function(
                builder.module, fnty, "llvm.prefetch.p0" if opaque else "llvm.prefetch.p0i8")
            builder.call(fn, [i8p, ir.Constant(i32, rw), ir.Constant(i32, 3), ir.Constant(i32, 1)])
            return context.get_dummy_value()

        return types.none(arr, i), codegen

    prefetch.__name__ = name
    prefetch.__doc__ = doc
    return intrinsic(prefetch)


prefetch_read = _prefetch(0, "prefetch_read",
                          "Start fetching arr[i]'s cache line to read it (x86: prefetcht0).")
prefetch_write = _prefetch(1, "prefetch_write",
                           "Start fetching arr[i]'s cache line to write it (x86: prefetchw).")

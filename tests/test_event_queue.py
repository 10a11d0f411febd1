"""The tournament event queue: incremental updates against a rebuild.

``update_queue`` after one slot's event changes, and ``update_queue_pair``
after a collision changed two (sharing their bucket and the climb above the
node where their paths meet), must leave exactly the tree ``build_queue``
builds from scratch, whatever the slots' buckets, the domain's offset and
hidden slots.  Times are drawn from a few values so that ties (ordered by
particle id) are common.
"""
import numpy as np
import pytest

from lockgraph.events import BUCKET, build_queue, tournament_size, update_queue, update_queue_pair


def _queue(evt, ids, hidden, lo, hi):
    q = tournament_size(hi - lo)
    tt = np.full(2 * q, np.inf)
    ts = np.full(2 * q, -1, np.int32)
    build_queue(tt, ts, evt, ids, hidden, lo, hi)
    return tt, ts


def _scene(rng, n):
    evt = rng.choice([0.1, 0.2, 0.3, 0.5, np.inf], n)
    ids = rng.permutation(n).astype(np.int64)
    hidden = (rng.random(n) < 0.1).astype(np.uint8)
    return evt, ids, hidden


@pytest.mark.parametrize("n, lo, hi", [(1, 0, 1), (37, 0, 37), (200, 0, 200), (200, 48, 131)])
class TestIncrementalUpdates:
    def test_one_slot(self, n, lo, hi):
        rng = np.random.default_rng(n + lo)
        evt, ids, hidden = _scene(rng, n)
        tt, ts = _queue(evt, ids, hidden, lo, hi)
        for _ in range(400):
            i = int(rng.integers(lo, hi))
            evt[i] = rng.choice([0.05, 0.2, 0.4, np.inf])
            if rng.random() < 0.1:
                hidden[i] ^= 1
            update_queue(tt, ts, evt, ids, hidden, lo, hi, i)
            rt, rs = _queue(evt, ids, hidden, lo, hi)
            assert np.array_equal(tt, rt) and np.array_equal(ts, rs)

    def test_pair_of_slots(self, n, lo, hi):
        """Collisions: both events change, the partner as often as not in the
        same bucket (storage is in tree order, partners are neighbours)."""
        rng = np.random.default_rng(7 * n + lo)
        evt, ids, hidden = _scene(rng, n)
        tt, ts = _queue(evt, ids, hidden, lo, hi)
        same = 0
        for _ in range(600):
            i = int(rng.integers(lo, hi))
            near = rng.random() < 0.5
            j = int(rng.integers(max(lo, i - BUCKET), min(hi, i + BUCKET))) if near \
                else int(rng.integers(lo, hi))
            if j == i:
                continue
            same += (i - lo) // BUCKET == (j - lo) // BUCKET
            evt[i] = rng.choice([0.05, 0.2, 0.4, np.inf])
            evt[j] = rng.choice([0.05, 0.2, 0.4, np.inf])
            if rng.random() < 0.1:
                hidden[i] ^= 1
            update_queue_pair(tt, ts, evt, ids, hidden, lo, hi, i, j)
            rt, rs = _queue(evt, ids, hidden, lo, hi)
            assert np.array_equal(tt, rt) and np.array_equal(ts, rs)
        if hi - lo > 1:
            assert same > 50  # the shared-bucket branch was exercised

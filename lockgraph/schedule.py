"""Which way a threaded engine runs a step's events (``schedule="auto"``).

A threaded step runs its tree, pair search and first predictions on all
threads.  Its events can then run on the worker threads (lock regions built
and classified, events handed between threads) or on the calling thread alone
(no lock structures).  Under the exact policy both give the sequential result
bit for bit, so the choice changes only the speed.

Which is faster depends on the system and changes as it evolves: where the
events are (a busy layer on one side of the cut between the threads' domains
leaves one thread idle), how many there are per particle (the lock
structures cost time in proportion to the particles), how much they cost
each.  Measured numbers: README, Threads.
"""


class EventSchedule:
    """Chooses, step by step, whether the events run on the worker threads.

    The cost of a step's events run one way is the wall time from its first
    predictions to its last event (a repair included), per event: the tree
    and pair search before are the same either way, and a system whose
    events per step rise or fall (a bed coming to rest, a marble arriving)
    would otherwise favour whichever way was measured when it had fewer.
    Each way's cost is a moving average (weight ``ALPHA`` for a new
    measurement).  The current way is kept until the other's cost is lower
    by more than ``MARGIN`` (a step's cost is noisy: without the margin the
    two ways alternate); the other way runs one step in every ``PROBE`` to
    keep its cost current, so a change is followed within a few ``PROBE``
    steps.  Each way is measured once before any choice.
    """

    PROBE = 16
    ALPHA = 0.5
    MARGIN = 0.05

    def __init__(self):
        self.cost = [None, None]  # moving averages, s per event: [threads, one thread]
        self.count = [0, 0]  # steps run each way
        self.one = False  # the current way: on one thread?
        self._steps = 0

    def sequential(self):
        """Run this step's events on the calling thread alone?"""
        self._steps += 1
        par, seq = self.cost
        if par is None:
            return False
        if seq is None:
            return True
        cur, other = (seq, par) if self.one else (par, seq)
        if other < cur * (1.0 - self.MARGIN):
            self.one = not self.one
        elif self._steps % self.PROBE == 0:
            return not self.one
        return self.one

    def record(self, sequential, seconds):
        """A step ran its events ``sequential``-ly at a cost of ``seconds`` per event."""
        k = int(bool(sequential))
        self.count[k] += 1
        c = self.cost[k]
        self.cost[k] = seconds if c is None else c + self.ALPHA * (seconds - c)

"""``EventSchedule``: the choice between running a step's events on the worker
threads or on one thread, from the measured step times (``schedule="auto"``)."""
from lockgraph.schedule import EventSchedule


def choices(sched, steps, cost_threads, cost_one):
    """Run the scheduler for ``steps`` steps with fixed costs; returns the ways
    chosen (True: one thread)."""
    out = []
    for k in range(steps):
        one = sched.sequential()
        out.append(one)
        sched.record(one, cost_one if one else cost_threads)
    return out


def test_each_way_is_measured_before_any_choice():
    s = EventSchedule()
    assert choices(s, 2, 1.0, 2.0) == [False, True]
    assert s.cost == [1.0, 2.0] and s.count == [1, 1]


def test_the_cheaper_way_runs_and_the_other_is_probed_every_PROBE_steps():
    s = EventSchedule()
    ways = choices(s, 4 * EventSchedule.PROBE, 2.0, 1.0)
    probes = [k for k, one in enumerate(ways) if not one]
    # step 1 (k = 0) measures the threads; after that one thread is cheaper, and
    # the threads run again only at every PROBE-th step
    assert probes == [0] + [k for k in range(1, len(ways)) if (k + 1) % EventSchedule.PROBE == 0]


def test_a_change_in_cost_is_followed_within_two_probes():
    s = EventSchedule()
    choices(s, 20, 2.0, 1.0)  # one thread cheaper
    ways = choices(s, 3 * EventSchedule.PROBE, 0.5, 1.0)  # now the threads are
    assert ways.index(False) < EventSchedule.PROBE  # the first probe
    run = [k for k in range(len(ways) - 2) if not any(ways[k:k + 3])]
    assert run and run[0] <= 2 * EventSchedule.PROBE  # switched at the second probe at most
    assert not s.one and ways[run[0]:].count(True) <= 1  # since: the probes only


def test_a_small_difference_does_not_switch():
    """Costs within MARGIN of each other: the current way stays (no alternating
    on noise)."""
    s = EventSchedule()
    ways = choices(s, 3 * EventSchedule.PROBE, 1.0, 1.0 - 0.5 * EventSchedule.MARGIN)
    assert ways[:2] == [False, True]
    assert ways[2:].count(True) <= 3  # the probes only


def test_moving_average():
    s = EventSchedule()
    s.record(False, 1.0)
    s.record(False, 3.0)
    assert s.cost[0] == 1.0 + EventSchedule.ALPHA * 2.0

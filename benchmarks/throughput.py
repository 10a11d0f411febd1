"""Collisions per second on one core, and memory per particle.

    python benchmarks/throughput.py [--quick] [--skip-memory] [--out results.json]

* gas at eta = 0.45, N = 4,000 and 32,000 (equilibrated state): pair
  collisions per second of wall time on one core, at the step and skin tuned for
  throughput (``GAS_TUNED``; the scene's own dt is shown beside it at 32,000).
  Reference point: a fast C++
  event-driven code reaches 3.9e5-9.5e5 collisions per CPU-second on this kind
  of machine; target here >= 4e5 at N = 32,000.
* ring and ring_moonlet (late states), dish and dish_marble (settled bed):
  collisions and particle-steps per second (the big body must not slow the
  small ones: compare the pairs).
* memory: peak resident memory per particle running ``ring`` at N = 1e6 (target
  <= 200 bytes), measured in a child process as (peak RSS - RSS after imports
  and compilation) / N, the state loaded from a file and handed to the
  simulation without a copy.

Timings on a shared virtual machine vary by 10-20% from minute to minute: each
figure is the best of ``--repeats`` interleaved runs, and the spread is shown.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, os.path.dirname(HERE))

from lockgraph import scenarios  # noqa: E402
from lockgraph.engine import Engine  # noqa: E402
from lockgraph.simulation import compile_kernels  # noqa: E402


# Gas step and skin for throughput: the sweep dt in {0.05, 0.075, 0.1} x skin in
# {0, 0.25, 0.35, 0.5, 0.75, 1} at N = 32,000 (2026-11-22, this machine) peaked at
# dt = 0.075 (about one collision per particle per step) with skin 0.75: a longer
# step spreads the per-step tree, pair search and first predictions over more
# collisions; a larger skin makes re-searches after speed-ups rare, at the price
# of longer candidate lists.  The scene's own dt = 0.05 is printed beside it.
GAS_TUNED = {"dt": 0.075, "skin": 0.75}


def timed_runs(cases, repeats, seconds):
    """Interleave the cases; each run lasts about ``seconds``.  Returns per-case
    lists of (collisions/s, particle-steps/s)."""
    engines = {}
    for name, (sc, steps_hint, opts) in cases.items():
        opts = dict(opts)
        eng = Engine(sc.state, sc.physics, opts.pop("dt", sc.dt), **opts)
        eng.step()  # first step: lists and pools grow to size
        engines[name] = eng
    out = {name: [] for name in cases}
    for _ in range(repeats):
        for name, eng in engines.items():
            sc, steps_hint, _ = cases[name]
            c0 = eng.totals[0] + eng.totals[1]
            t0 = time.perf_counter()
            steps = 0
            while True:
                eng.step()
                steps += 1
                if steps >= steps_hint and time.perf_counter() - t0 > seconds:
                    break
            w = time.perf_counter() - t0
            c = eng.totals[0] + eng.totals[1] - c0
            out[name].append((c / w, sc.state.n * steps / w))
    return out


def memory_child(path, n, steps):
    """Run in a fresh interpreter: prints peak bytes per particle."""
    code = f"""
import numpy as np, json
from lockgraph import scenarios
from lockgraph.simulation import Simulation, compile_kernels
from lockgraph.state import State
from lockgraph.domains import ShearingSheet
from lockgraph.physics import Physics
compile_kernels()
sc = scenarios.load("ring", n=1000)
def rss():
    with open('/proc/self/statm') as f:
        return int(f.read().split()[1]) * 4096
def hwm():
    for line in open('/proc/self/status'):
        if line.startswith('VmHWM'):
            return int(line.split()[1]) * 1024
base = rss()
open('/proc/self/clear_refs', 'w').write('5')  # reset the high-water mark
st = State.load({path!r})
lx = float(np.load({path!r} + '.lx.npy'))
ph = Physics(ShearingSheet(lx, lx, sc.params['omega']), sc.physics.forces,
             sc.physics.restitution)
sim = Simulation(st, ph, dt=sc.dt, copy=False)
del st
sim.run({steps})
print(json.dumps({{"bytes_per_particle": (hwm() - base) / {n}, "collisions": sim.stats["collisions"],
                  "wall_s": sim.stats["wall_s"]}}))
"""
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                       cwd=os.path.dirname(HERE))
    if p.returncode != 0:
        raise RuntimeError(p.stderr)
    return json.loads(p.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="shorter runs, no N = 1e6 memory run")
    ap.add_argument("--skip-memory", action="store_true")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", help="write the results as JSON")
    args = ap.parse_args()
    seconds = 1.0 if args.quick else 3.0
    t0 = time.perf_counter()
    compile_s = compile_kernels()
    print(f"compile (or load from numba's cache): {compile_s:.1f} s", flush=True)
    results = {"compile_s": compile_s}
    say = lambda m: print(m, file=sys.stderr, flush=True)  # noqa: E731

    cases = {}
    for n in (4000, 32000):
        say(f"preparing gas N={n} (equilibrating)")
        sc = scenarios.load("gas", "late", n=n, params={"late_time": 5.0})
        cases[f"gas eta=0.45 N={n}"] = (sc, 3, GAS_TUNED)
        if n == 32000:
            # the scene's own step and skin, side by side with the tuned ones
            cases[f"gas N={n} dt={sc.dt:g} skin=0.5"] = (sc, 3, {})
    say("preparing ring and ring_moonlet (late), dish and dish_marble (settled)")
    cases["ring late N=20000"] = (scenarios.load("ring", "late", n=20000, progress=say), 5, {})
    cases["ring_moonlet late N=20000"] = (scenarios.load("ring_moonlet", "late", n=20000,
                                                         progress=say), 5, {})
    cases["dish settled N=2000"] = (scenarios.load("dish", "late", n=2000, progress=say),
                                    20, {})
    cases["dish_marble settled N=2001"] = (scenarios.load("dish_marble", "late", n=2001,
                                                          progress=say), 20, {})
    runs = timed_runs(cases, args.repeats, seconds)
    print(f"\n{'case':28s} {'collisions/s (best)':>20s} {'spread':>9s} {'particle-steps/s':>17s}")
    for name, vals in runs.items():
        c = [v[0] for v in vals]
        ps = [v[1] for v in vals]
        print(f"{name:28s} {max(c):20.3g} {min(c) / max(c):9.2f} {max(ps):17.3g}")
        results[name] = {"collisions_per_s": max(c), "collisions_per_s_all": c,
                         "particle_steps_per_s": max(ps)}
    best = results["gas eta=0.45 N=32000"]["collisions_per_s"]
    print(f"\ngas N=32000: {best:.3g} collisions/s on one core; target 4e5 -> ratio "
          f"{best / 4e5:.2f}; C++ reference range 3.9e5-9.5e5 -> {best / 3.9e5:.2f}-"
          f"{best / 9.5e5:.2f}")
    if not (args.quick or args.skip_memory):
        n = 1_000_000
        say("memory: generating ring N=1e6")
        sc = scenarios.load("ring", n=n)
        with tempfile.TemporaryDirectory() as tmp:
            path = os.path.join(tmp, "ring.npz")
            sc.state.save(path)
            np.save(path + ".lx.npy", sc.physics.domain.lx)
            del sc
            m = memory_child(path, n, 5)
        print(f"\nring N=1e6: peak memory {m['bytes_per_particle']:.0f} bytes per particle "
              f"(target <= 200); 5 steps in {m['wall_s']:.1f} s")
        results["memory_ring_1e6"] = m
    print(f"\nbenchmark wall time {time.perf_counter() - t0:.0f} s")
    if args.out:
        with open(args.out, "w") as fh:
            json.dump(results, fh, indent=1)


if __name__ == "__main__":
    main()

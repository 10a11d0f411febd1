"""Campaigns: many runs, each cached on disk by its parameters, run here or on Dask.

A ``Run`` is a kind (a function registered in ``report_runs.KINDS``) and its
parameters.  Its result (a JSON-able dict) is written to
``CACHE/<kind>-<key>.json`` atomically (a temporary file renamed into place),
so an interrupted campaign leaves only whole results and the next one resumes
where it stopped.  The key hashes the kind, the parameters and
``CACHE_VERSION`` (raise it when a run's meaning changes).

By default the runs go one after another in this process: they are timed, and
two runs sharing a 2-core machine would each be slowed by the other.  With
``scheduler`` they go to a Dask distributed cluster ("local": a local cluster
of one worker process; else the scheduler's address), which runs them
concurrently; their wall times are then marked ``concurrent``.
"""
import hashlib
import json
import os
import sys
import time
import traceback
from dataclasses import dataclass, field

from .errors import InputError

CACHE_VERSION = 5


@dataclass(frozen=True)
class Run:
    """One run of a campaign.

    kind : str — a key of ``report_runs.KINDS``.
    params : dict — its keyword arguments (JSON-able).
    label : str — how charts and tables name it.
    group : str — which part of the report it feeds (e.g. "ring/speed").
    """
    kind: str
    params: dict = field(hash=False)
    label: str = ""
    group: str = ""

    @property
    def key(self):
        blob = json.dumps({"kind": self.kind, "params": self.params, "v": CACHE_VERSION},
                          sort_keys=True)
        return f"{self.kind}-{hashlib.sha1(blob.encode()).hexdigest()[:16]}"


class Cache:
    """Finished results on disk, one JSON file per run."""

    def __init__(self, directory):
        self.directory = str(directory)
        os.makedirs(self.directory, exist_ok=True)
        self._sweep()

    def _sweep(self):
        """Remove temporary files left by a campaign that was killed mid-write
        (their writer's pid is gone)."""
        for name in os.listdir(self.directory):
            if name.endswith(".tmp"):
                pid = name[:-4].rsplit(".", 1)[-1]
                if pid.isdigit() and not _alive(int(pid)):
                    os.remove(os.path.join(self.directory, name))

    def path(self, run):
        return os.path.join(self.directory, run.key + ".json")

    def get(self, run):
        """The stored result of ``run``, or None."""
        try:
            with open(self.path(run)) as fh:
                return json.load(fh)["result"]
        except (FileNotFoundError, json.JSONDecodeError, KeyError):
            return None

    def put(self, run, result):
        path = self.path(run)
        tmp = f"{path}.{os.getpid()}.tmp"
        with open(tmp, "w") as fh:
            json.dump({"kind": run.kind, "params": run.params, "label": run.label,
                       "result": result}, fh)
        os.replace(tmp, path)


def _alive(pid):
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


class Bars:
    """Progress on stderr: the campaign (runs done of all) and the current run.

    On a terminal one line is redrawn in place; otherwise a line is printed at
    most every ``every`` seconds and when a run ends."""

    def __init__(self, total, stream=None, every=10.0, width=24):
        self.total = total
        self.done = 0
        self.stream = stream or sys.stderr
        self.tty = self.stream.isatty()
        self.every = every
        self.width = width
        self.t0 = time.perf_counter()
        self.last = -1e9
        self.label = ""

    def _bar(self, frac):
        k = int(round(self.width * min(max(frac, 0.0), 1.0)))
        return "#" * k + "." * (self.width - k)

    def _emit(self, line, force):
        now = time.perf_counter()
        if self.tty:
            self.stream.write("\r" + line[:160].ljust(160))
            if force:
                self.stream.write("\n")
        elif force or now - self.last >= self.every:
            self.stream.write(line + "\n")
        else:
            return
        self.last = now
        self.stream.flush()

    def start(self, label):
        self.label = label
        self.run_t0 = time.perf_counter()
        self.update(0.0)

    def update(self, frac, note=""):
        """The current run is ``frac`` (0..1) done."""
        overall = (self.done + frac) / max(self.total, 1)
        line = (f"[{self._bar(overall)}] {self.done}/{self.total} runs "
                f"{time.perf_counter() - self.t0:6.0f} s | {self.label} "
                f"[{self._bar(frac)[:12]}] {100 * frac:3.0f}% {note}")
        self._emit(line, False)

    def finish(self, label, how):
        self.done += 1
        self._emit(f"[{self._bar(self.done / max(self.total, 1))}] {self.done}/{self.total} "
                   f"runs {time.perf_counter() - self.t0:6.0f} s | {label}: {how}", True)


def execute(run, progress=None):
    """Run one ``Run`` here; returns its result dict.  An exception becomes a
    result with ``failed`` (the message) so that one broken run does not end
    the campaign; failed results are not cached."""
    from .report_runs import KINDS

    fn = KINDS[run.kind]
    try:
        out = fn(progress=progress or (lambda frac, note="": None), **run.params)
    except Exception as exc:  # reported in the report's table of failed runs
        return {"failed": f"{type(exc).__name__}: {exc}",
                "traceback": traceback.format_exc(limit=4)}
    out.setdefault("concurrent", False)
    return out


def _execute_remote(run):
    out = execute(run)
    out["concurrent"] = True
    out["host"] = os.uname().nodename
    return out


def _client(scheduler):
    try:
        from distributed import Client, LocalCluster
    except ImportError:
        raise InputError("scheduler", "needs Dask distributed: pip install 'dask[distributed]'")
    if scheduler == "local":
        cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True,
                               dashboard_address=None)
        return Client(cluster), cluster
    return Client(scheduler, timeout=30), None


def run_campaign(runs, cache, scheduler=None, stream=None, every=10.0):
    """Results of every run ({run.key: result}), computing those not cached.

    ``scheduler``: None (here, one after another), "local" or a Dask scheduler
    address.  Progress goes to ``stream`` (stderr)."""
    results, todo = {}, []
    for r in runs:
        got = cache.get(r)
        if got is None:
            todo.append(r)
        else:
            results[r.key] = got
    unique = list({r.key: r for r in todo}.values())
    bars = Bars(len(unique), stream, every)
    print(f"campaign: {len(runs)} runs, {len(runs) - len(todo)} from the cache "
          f"({cache.directory}), {len(unique)} to run"
          + (f" on Dask ({scheduler})" if scheduler and unique else ""),
          file=bars.stream, flush=True)
    if not unique:
        return results
    if scheduler is None:
        for r in unique:
            bars.start(r.label or r.kind)
            out = execute(r, bars.update)
            _store(cache, r, out, results, bars)
    else:
        from distributed import as_completed

        client, cluster = _client(scheduler)
        try:
            futures = {client.submit(_execute_remote, r, pure=False, key=r.key): r
                       for r in unique}
            for fut in as_completed(futures):
                _store(cache, futures[fut], fut.result(), results, bars)
        finally:
            client.close()
            if cluster is not None:
                cluster.close()
    return results


def _store(cache, run, out, results, bars):
    results[run.key] = out
    if "failed" in out:
        bars.finish(run.label or run.kind, f"FAILED ({out['failed']})")
        return
    cache.put(run, out)
    wall = out.get("wall_s")
    bars.finish(run.label or run.kind,
                f"done, {wall:.1f} s" if isinstance(wall, (int, float)) else "done")

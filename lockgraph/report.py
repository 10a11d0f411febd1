"""``lockgraph report``: run a campaign and write ``DIR/index.html``.

The page answers, with numbers measured on this machine, how fast each method
is, how accurate, and where each breaks down: one speed-accuracy chart per
scene (Pareto front drawn), the paper's Tables 1-4 measured here (2 threads
measured, 16 threads by replay, the paper's published times beside), a table
of failures with the figure that shows each, and pictures of the scenes and
of the lock graph.  Raw results sit beside the page: ``results.json`` (every
run, its parameters and its result) and one CSV per table.  Every file is
written whole (a temporary file renamed into place); finished runs are cached
in ``DIR/cache`` so an interrupted report resumes.
"""
import csv
import html
import io
import json
import math
import os
import platform
import sys
import time

import numpy as np

from . import __version__, report_charts as C
from . import report_plan as P
from . import report_tables as T
from .campaign import Cache, run_campaign
from .reference_codes import MissingReference

CODES_OF = {"ring": ("rebound",), "ring_moonlet": ("rebound",), "dish": ("lammps", "liggghts"),
            "dish_marble": ("lammps", "liggghts")}
TITLES = {"ring": "Planetary ring (shearing sheet)", "ring_moonlet": "Ring with a moonlet",
          "dish": "Dish: grains settling", "dish_marble": "Dish: marble dropped into the bed"}
XLABEL = {"ring": "error: collisions or sigma_x vs converged lockgraph (relative)",
          "ring_moonlet": "error: collisions or sigma_x vs converged lockgraph (relative)",
          "dish": "error: kinetic energy vs LAMMPS reference (fraction of peak)",
          "dish_marble": "error: penetration depth vs LAMMPS reference (grain diameters)"}


def check_codes(scenes):
    """Raise MissingReference naming the first reference code that is missing."""
    from . import reference_codes as R

    need = {c for s in scenes for c in CODES_OF[s]}
    if "rebound" in need:
        R.rebound()
    if "lammps" in need:
        R.lammps_binary()
        R.mpirun("lammps")
    if "liggghts" in need:
        R.liggghts_binary()


def _write(path, text):
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)


def _csv(path, rows):
    if not rows:
        return
    cols = list(dict.fromkeys(k for r in rows for k in r))
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=cols)
    w.writeheader()
    w.writerows(rows)
    _write(path, buf.getvalue())


def build(out, mode="quick", scenes=P.SCENES, scheduler=None, cache_dir=None, stream=None,
          pictures=True):
    """Run the campaign and write the report into ``out``; returns a summary
    dict (paths, counts, wall time)."""
    t0 = time.perf_counter()
    scenes = list(scenes)
    runs = P.plan(mode, scenes)
    check_codes(scenes)
    os.makedirs(out, exist_ok=True)
    cache = Cache(cache_dir or os.path.join(out, "cache"))
    cached = sum(cache.get(r) is not None for r in runs)
    if cached < len(runs) and scheduler is None:
        from .simulation import compile_kernels

        say = stream or sys.stderr
        print("compiling lockgraph's numba kernels (the first time after an install takes "
              "a minute or two; cached on disk after)", file=say, flush=True)
        print(f"  {compile_kernels():.1f} s", file=say, flush=True)
    results = run_campaign(runs, cache, scheduler, stream)
    page = Page(out)
    speed = {}
    for s in scenes:
        rows, floor = (T.ring_rows(s, runs, results) if s.startswith("ring")
                       else T.dish_rows(runs, results) if s == "dish"
                       else T.marble_rows(runs, results))
        speed[s] = (rows, floor)
    tables = {s: T.table_rows(s, runs, results) for s in scenes}
    fails = failure_rows(runs, results, speed, tables, out)
    failed = [(r, results[r.key]["failed"]) for r in runs if "failed" in results[r.key]]
    page.header(mode, scenes, len(runs), cached, scheduler)
    if pictures:
        page.pictures(scenes, mode)
    page.speed(speed)
    page.tables(tables)
    page.failures(fails)
    page.failed_runs(failed)
    page.footer(time.perf_counter() - t0)
    _csv(os.path.join(out, "speed_accuracy.csv"), [r for rs, _ in speed.values() for r in rs])
    _csv(os.path.join(out, "paper_tables.csv"), [r for rs, _ in tables.values() for r in rs])
    _csv(os.path.join(out, "failures.csv"), [{k: v for k, v in f.items()} for f in fails])
    _write(os.path.join(out, "results.json"), json.dumps(
        {"mode": mode, "scenes": scenes, "lockgraph": __version__,
         "runs": [{"key": r.key, "kind": r.kind, "label": r.label, "group": r.group,
                   "params": r.params, "result": results[r.key]} for r in runs]}, indent=1))
    index = page.write()
    return {"index": index, "runs": len(runs), "cached": cached, "failed": len(failed),
            "wall_s": time.perf_counter() - t0}


def _results(runs, results, group):
    return [(r, results[r.key]) for r in runs
            if r.group == group and "failed" not in results.get(r.key, {"failed": 1})]


def failure_rows(runs, results, speed, tables, out):
    """One row per failure mode found in this campaign: what, where, the
    measured evidence and the figure that shows it (a PNG in ``out``)."""
    rows = []
    fail = _results(runs, results, "failures")
    by_kind = {}
    for r, res in fail:
        by_kind.setdefault(r.kind, []).append((r, res))
    # inelastic collapse without the guard
    col = {res["guard"]: res for _, res in by_kind.get("collapse", [])}
    if col:
        png = C.series([(("with" if g else "without") + " the collapse guard",
                         np.arange(1, len(res["collisions_per_step"]) + 1) * res["dt"],
                         np.maximum(res["collisions_per_step"], 0.5))
                        for g, res in sorted(col.items())],
                       os.path.join(out, "fail_collapse.png"), "Dish: collisions per step",
                       "time (s)", "collisions per step", logy=True)
        bare = col.get(False)
        ev = (f"without the guard the run stopped at t = {bare['time_reached']:.4f} s: "
              f"\u201c{bare['diagnosis']}\u201d" if bare and bare["stopped"]
              else "without the guard the run did not collapse in this time")
        if True in col:
            ev += (f"; with the guard it reached t = {col[True]['time_reached']:.3f} s, at most "
                   f"{max(col[True]['collisions_per_step'] or [0])} collisions per step")
        rows.append({"failure": "inelastic collapse without the collapse guard",
                     "method": "lockgraph (hard spheres, e < 1)", "scene": "dish",
                     "detected": bool(bare and bare["stopped"]), "evidence": ev,
                     "figure": os.path.basename(png)})
    # DEM with a time step too large
    big = by_kind.get("dish_dem", [])
    if big:
        curves = [(r.label, res["times"], np.maximum(res["ke"], 1e-12)) for r, res in big]
        good = [(r.label, res) for r, res in _results(runs, results, "dish/speed")
                if r.kind == "dish_dem" and r.params.get("ranks", 1) == 1]
        if good:
            lab, res = good[0]
            curves.append((lab + " (dt = t_c/20)", res["times"], np.maximum(res["ke"], 1e-12)))
        png = C.series(curves, os.path.join(out, "fail_dem_dt.png"),
                       "Dish: kinetic energy, DEM step too large", "time (s)",
                       "kinetic energy (J)", logy=True)
        for r, res in big:
            f = res.get("failures") or {}
            rows.append({"failure": "DEM time step too large (dt = 2 t_c)",
                         "method": r.label.split(" ")[0], "scene": "dish",
                         "detected": bool(f),
                         "evidence": (f"{f.get('lost_particles', 0)} grains lost, mechanical "
                                      f"energy gained x{f.get('energy_gain', 0):.3g}" if f
                                      else "no failure seen"),
                         "figure": os.path.basename(png)})
    # REBOUND overlaps and sinking (the moonlet)
    for scene in ("ring_moonlet", "ring"):
        reb = [(r, res) for r, res in _results(runs, results, f"{scene}/speed")
               if r.kind == "ring_rebound"]
        if not reb:
            continue
        lg = [res for r, res in _results(runs, results, f"{scene}/speed")
              if r.label == "lockgraph sequential"]
        png = C.bars([r.label.replace("REBOUND ", "") for r, _ in reb]
                     + ["lockgraph"], [100 * res["max_overlap"] for _, res in reb]
                     + [100 * lg[0]["max_overlap"] if lg else None],
                     os.path.join(out, f"fail_overlap_{scene}.png"),
                     f"{TITLES[scene]}: largest overlap resolved", "% of a contact distance",
                     logy=True)
        rows.append({"failure": "REBOUND resolves collisions late: overlaps"
                                + (" and the moonlet sinks into the ring" if scene ==
                                   "ring_moonlet" else ""),
                     "method": "REBOUND", "scene": scene,
                     "detected": any(res["overlapping"] for _, res in reb),
                     "evidence": "; ".join(
                         f"{r.label.replace('REBOUND ', '')}: {res['overlapping']} overlapping "
                         f"(largest {100 * res['max_overlap']:.1f} %), with the largest body "
                         f"{res['largest_overlapping']} (up to "
                         f"{100 * res['largest_max_overlap']:.1f} %), {res['lost']} lost"
                         for r, res in reb)
                     + (f"; lockgraph: largest overlap {lg[0]['max_overlap']:.2g}" if lg else ""),
                     "figure": os.path.basename(png)})
    # grid locks and large SCALE with a big body: few lock regions, so events
    # that could run together wait (the tables' 2-thread runs and replays)
    for scene, what in (("dish_marble", "grid"), ("ring_moonlet", "graph 8")):
        rws, by_state = tables.get(scene, ([], {}))
        if not by_state:
            continue
        names = [r["lock"] for r in rws]
        state = "late" if "late" in by_state else next(iter(by_state))
        regions = {k: _regions(by_state[state], k) for k in names}
        png = C.bars(names, [regions[k] for k in names],
                     os.path.join(out, f"fail_regions_{scene}.png"),
                     f"{TITLES[scene]} ({state}, N = {by_state[state]['n']}): lock regions "
                     "holding particles", "regions", logy=True)
        mine = {r["lock"]: r for r in rws}[what]
        fine = regions.get("graph 1.2") or 0
        few = regions[what] is not None and regions[what] * 4 <= fine
        ev = (f"{state}: {what} gives {regions[what]} occupied lock regions, SCALE 1.2 "
              f"{fine}; " + "; ".join(
                  f"{st}: {what} {mine[f'{st}_replay_ms']:.2f} ms replayed at 16 threads "
                  f"({mine[f'{st}_replay_over_grid']:.2f} of the grid's), concurrency "
                  f"{mine[f'{st}_concurrency']:.1f}" for st in by_state))
        rows.append({"failure": ("grid locks with the marble: cells as large as the marble's "
                                 "reach" if what == "grid" else
                                 "large SCALE with a big body: few, large lock regions"),
                     "method": f"lockgraph {what}", "scene": scene, "detected": few,
                     "evidence": ev, "figure": os.path.basename(png)})
    # the paper's policy: ordering violations
    for r, res in by_kind.get("policy_check", []):
        scene = r.params["scene"]
        png = C.series([(f"{k} policy", np.arange(1, len(res[k]["violations_per_step"]) + 1),
                         res[k]["violations_per_step"]) for k in ("exact", "paper")],
                       os.path.join(out, f"fail_policy_{scene}.png"),
                       f"{TITLES[scene]}: causality violations per step (2 threads)", "step",
                       "violations")
        pa, ex = res["paper"], res["exact"]
        rows.append({"failure": "the paper's lock rule: events out of time order",
                     "method": "lockgraph, paper policy", "scene": scene,
                     "detected": pa["violations"] > 0 or not pa["identical"],
                     "evidence": (f"paper policy: {pa['violations']} violations, final state "
                                  f"{'identical' if pa['identical'] else 'differs'} (largest "
                                  f"position difference {pa['max_position_difference']:.3g} m); "
                                  f"exact policy: {ex['violations']} detected, "
                                  f"{ex['repairs']} steps repaired, final state "
                                  f"{'bitwise identical' if ex['identical'] else 'DIFFERS'}"),
                     "figure": os.path.basename(png)})
    return rows


def _regions(res, lock):
    """Occupied lock regions of one lock configuration in a table's run."""
    stats = res["locks"].get(lock, {}).get("lock_stats") or {}
    return stats.get("occupied", stats.get("regions"))


def _fmt(x, digits=3):
    if x is None:
        return "&ndash;"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return f"{x:,}"
    if isinstance(x, float):
        if not math.isfinite(x):
            return "&ndash;"
        return f"{x:.{digits}g}"
    return html.escape(str(x))


class Page:
    """The HTML page, built section by section."""

    def __init__(self, out):
        self.out = out
        self.parts = []
        self.images = []

    def h(self, level, text, ident=None):
        idattr = f' id="{ident}"' if ident else ""
        self.parts.append(f"<h{level}{idattr}>{html.escape(text)}</h{level}>")

    def p(self, text):
        self.parts.append(f"<p>{text}</p>")

    def img(self, name, alt):
        self.images.append(name)
        self.parts.append(f'<figure><img src="{html.escape(name)}" alt="{html.escape(alt)}">'
                          f"<figcaption>{html.escape(alt)}</figcaption></figure>")

    def table(self, head, rows, cls=None):
        c = f' class="{cls}"' if cls else ""
        out = [f"<table{c}><thead><tr>"
               + "".join(f"<th>{html.escape(h)}</th>" for h in head) + "</tr></thead><tbody>"]
        for r in rows:
            out.append("<tr>" + "".join(f"<td>{v}</td>" for v in r) + "</tr>")
        out.append("</tbody></table>")
        self.parts.append("".join(out))

    def header(self, mode, scenes, nruns, cached, scheduler):
        cpu = platform.processor() or platform.machine()
        try:
            with open("/proc/cpuinfo") as fh:
                cpu = next(ln.split(":", 1)[1].strip() for ln in fh if ln.startswith("model name"))
        except (OSError, StopIteration):
            pass
        self.h(1, "lockgraph: speed, accuracy and where methods fail")
        self.p(f"Measured {time.strftime('%Y-%m-%d %H:%M')} on {html.escape(cpu)}, "
               f"{os.cpu_count()} cores; lockgraph {__version__}; mode <b>{mode}</b>; "
               f"scenes {', '.join(scenes)}; {nruns} runs, {cached} from the cache"
               + (f"; runs on Dask ({html.escape(str(scheduler))}): their wall times shared "
                  "the workers' cores" if scheduler else
                  "; runs one after another in one process (wall times undisturbed by each "
                  "other)") + ".")
        self.p('Sections: <a href="#pictures">pictures</a>, <a href="#speed">speed against '
               'accuracy</a>, <a href="#tables">the paper\'s tables</a>, <a href="#failures">'
               'where methods fail</a>. Raw results: <a href="results.json">results.json</a>, '
               '<a href="speed_accuracy.csv">speed_accuracy.csv</a>, <a href="paper_tables.csv">'
               'paper_tables.csv</a>, <a href="failures.csv">failures.csv</a>.')

    def pictures(self, scenes, mode):
        from . import pictures, scenarios

        self.h(2, "Pictures", "pictures")
        sizes = P.TABLES[mode][0]
        for s in scenes:
            n = min(sizes[s], 20001)
            sc = scenarios.load(s, "late", n=n)
            name = f"snapshot_{s}.png"
            pictures.scene_snapshot(sc, os.path.join(self.out, name), f"{TITLES[s]}, N = {n}")
            self.img(name, f"{TITLES[s]}: late state, N = {n}")
            # the marble's dish at these sizes is one lock region: the dish shows the graph
            if s in ("ring", "ring_moonlet", "dish"):
                name = f"lockgraph_{s}.png"
                info = pictures.lock_graph_figure(sc, os.path.join(self.out, name), 4.0,
                                                  f"Lock graph, {TITLES[s]}, SCALE 4")
                self.img(name, f"Lock graph of the {s} late state at SCALE 4: "
                               f"{info['regions']} regions (node size: particles in the "
                               f"region), {info['edges']} adjacencies")

    def speed(self, speed):
        self.h(2, "Speed against accuracy", "speed")
        self.p("Each point is one run from the same state: wall time against its error "
               "relative to the converged reference (see each chart's axis). Lower left is "
               "better; the dashed line is the Pareto front. Parallel lockgraph runs use the "
               "exact policy: their results are checked to be bitwise those of the sequential "
               "run, so they differ from it in wall time only.")
        for s, (rows, floor) in speed.items():
            self.h(3, TITLES[s])
            if not rows:
                self.p("No finished runs (see the failed runs below).")
                continue
            name = f"speed_{s}.png"
            C.speed_accuracy(rows, os.path.join(self.out, name),
                             f"{TITLES[s]}, N = {rows[0]['n']}", XLABEL[s], floor)
            self.img(name, f"{TITLES[s]}: wall time against error")
            front = {r["method"] for r in C.pareto([r for r in rows if not r.get("reference")])}
            self.table(["method", "wall s", "error", "Pareto", "notes"],
                       [[html.escape(r["method"]), _fmt(r["wall_s"]), _fmt(r["error"]),
                         _fmt(r["method"] in front), html.escape(r["note"])] for r in rows],
                       cls=f"speed speed-{s}")
            if floor is not None:
                self.p(f"Noise floor (chaotic scatter of converged runs): {floor:.3g}.")

    def tables(self, tables):
        self.h(2, "The paper's tables, measured here", "tables")
        self.p("Rows: lock graph at SCALE 1.2&ndash;8 and the 2-D grid. Events phase of one "
               "scene's traced steps: measured on 2 threads, and replayed at 16 threads "
               "(queue overhead fitted to the 2-thread measurement). The paper's times are "
               "whole runs of 10 steps on 16 cores at ~200,000 particles: compare the shape "
               "(the /grid columns), not the seconds.")
        for s, (rows, by_state) in tables.items():
            self.h(3, f"{TITLES[s]}")
            if not by_state:
                self.p("No finished runs (see the failed runs below).")
                continue
            head = ["lock"]
            for st in ("early", "late"):
                head += [f"{st}: 2 threads ms", f"{st}: 16 (replay) ms", f"{st}: /grid",
                         f"{st}: concurrency", f"{st}: paper s", f"{st}: paper /grid"]
            body = []
            for r in rows:
                line = [html.escape(r["lock"])]
                for st in ("early", "late"):
                    line += [_fmt(r[f"{st}_measured2_ms"]), _fmt(r[f"{st}_replay_ms"]),
                             _fmt(r[f"{st}_replay_over_grid"]), _fmt(r[f"{st}_concurrency"]),
                             _fmt(r[f"{st}_paper_s"]) if r[f"{st}_paper_s"] is not None
                             else "&gt;&gt; 150000", _fmt(r[f"{st}_paper_over_grid"])]
                body.append(line)
            self.table(head, body, cls=f"paper paper-{s}")
            ns = ", ".join(f"{st} N = {res['n']}, {res['events']} events in {res['steps']} "
                           f"steps" for st, res in by_state.items())
            self.p(html.escape(ns))
            name = f"tables_{s}.png"
            C.replay_curves(by_state, os.path.join(self.out, name), TITLES[s])
            self.img(name, f"{TITLES[s]}: events phase against threads (replay) and measured")

    def failures(self, rows):
        self.h(2, "Where methods fail", "failures")
        self.p("Each failure mode is provoked on purpose; the evidence is measured in this "
               "campaign, and \u201cdetected\u201d says whether the failure was caught and "
               "reported by the code or the harness.")
        self.table(["failure", "method", "scene", "detected", "evidence", "figure"],
                   [[html.escape(f["failure"]), html.escape(f["method"]), f["scene"],
                     _fmt(f["detected"]), html.escape(f["evidence"]),
                     f'<a href="{f["figure"]}">{f["figure"]}</a>'] for f in rows],
                   cls="failures")
        for f in dict.fromkeys(f["figure"] for f in rows):
            self.img(f, f)

    def failed_runs(self, failed):
        if not failed:
            return
        self.h(2, "Runs that failed", "failed")
        self.table(["run", "error"], [[html.escape(r.label), html.escape(msg)]
                                      for r, msg in failed], cls="failed")

    def footer(self, wall):
        self.p(f"Report built in {wall:.0f} s.")

    def write(self):
        style = ("body{font-family:sans-serif;max-width:1200px;margin:1em auto;padding:0 1em}"
                 "table{border-collapse:collapse;font-size:12px;margin:.5em 0}"
                 "td,th{border:1px solid #bbb;padding:2px 5px;vertical-align:top}"
                 "figure{display:inline-block;margin:.5em}img{max-width:100%}"
                 "figcaption{font-size:11px;color:#444}")
        text = ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\">"
                "<title>lockgraph report</title><style>" + style + "</style></head><body>\n"
                + "\n".join(self.parts) + "\n</body></html>\n")
        path = os.path.join(self.out, "index.html")
        _write(path, text)
        return path


__all__ = ["build", "check_codes", "MissingReference"]

"""From a campaign's results to the report's rows: errors against the converged
references, the paper's tables, and the evidence of each failure.

Errors (each row's ``error``, lower is better):

- ring scenes: the larger of two relative errors — the collision count over
  the run and the velocity dispersion sigma_x (mean of 10 snapshots) —
  against the mean of lockgraph at dt/2, dt/4 and dt/8 (its only dt error is
  the splitting of Hill's equations).  Noise floor: twice the rms error of
  those three about their mean (chaos alone separates them).
- dish: the largest difference of the seed-mean kinetic energy (sampled every
  10 ms) from the reference's, over the reference's peak; reference: LAMMPS at
  the stiffest contact run (a soft-sphere code converges to hard spheres as
  its contacts stiffen).
- dish_marble: the penetration depth's difference from the reference's, in
  grain diameters.
"""
import math

import numpy as np

from .paper_tables import LOCKS, PAPER, key_name

FAMILIES = ("lockgraph", "lockgraph 2 threads", "REBOUND", "LAMMPS", "LAMMPS 2 ranks",
            "LIGGGHTS")


def _family(label):
    if label.startswith("lockgraph"):
        return "lockgraph 2 threads" if "2 threads" in label else "lockgraph"
    if label.startswith("LAMMPS"):
        return "LAMMPS 2 ranks" if "2 ranks" in label else "LAMMPS"
    return label.split(" ", 1)[0]


def _setting(label):
    return label.split(" ", 1)[1] if " " in label else label


def _by_label(runs, results, group):
    """{label: [results of its seeds]} of the runs in ``group`` that finished."""
    out = {}
    for r in runs:
        res = results.get(r.key)
        if r.group == group and res is not None and "failed" not in res:
            out.setdefault(r.label, []).append(res)
    return out


def _mean_finite(xs):
    xs = [x for x in xs if x is not None and math.isfinite(x)]
    return float(np.mean(xs)) if xs else None


def _rel(a, b):
    return abs(a - b) / abs(b) if b else math.inf


def ring_rows(scene, runs, results):
    """(rows, noise floor) of a ring scene's speed-accuracy chart."""
    refs = [v[0] for v in _by_label(runs, results, f"{scene}/reference").values()]
    if not refs:
        return [], None
    ref = {k: float(np.mean([r[k] for r in refs])) for k in ("collisions", "sigma_x")}

    def err(r):
        return max(_rel(r["collisions"], ref["collisions"]), _rel(r["sigma_x"], ref["sigma_x"]))

    e = [err(r) for r in refs]
    floor = 2.0 * math.sqrt(sum(x * x for x in e) / max(len(e) - 1, 1))
    speed = _by_label(runs, results, f"{scene}/speed")
    seq = speed.get("lockgraph sequential", [{}])[0].get("state_hash")
    rows = []
    for label, (r,) in speed.items():
        note = ""
        if label.startswith("REBOUND"):
            note = (f"{r['overlapping']} collisions resolved overlapping (largest "
                    f"{100 * r['max_overlap']:.1f} % of a contact distance); "
                    f"{r['lost']} particles lost")
            if r.get("largest_overlapping"):
                note += (f"; {r['largest_overlapping']} with the largest body (up to "
                         f"{100 * r['largest_max_overlap']:.1f} %)")
        elif "threads" in label:
            same = r["state_hash"] == seq
            note = ("final state bitwise identical to the sequential run" if same
                    else "final state DIFFERS from the sequential run")
            note += (f"; {r['violations']} causality violations detected, {r['repairs']} "
                     f"steps repaired; mean concurrency {r['mean_concurrency']:.2f}")
        rows.append({"scene": scene, "method": label, "family": _family(label),
                     "setting": _setting(label), "wall_s": r["wall_s"], "error": err(r),
                     "collisions": r["collisions"], "sigma_x": r["sigma_x"],
                     "max_overlap": r["max_overlap"], "n": r["n"], "note": note,
                     "identical": r.get("state_hash") == seq if "threads" in label else None})
    return rows, floor


def dish_rows(runs, results):
    """(rows, noise floor or None) of the settling dish."""
    refs = _by_label(runs, results, "dish/reference")
    if not refs:
        return [], None
    (ref_label, ref_runs), = refs.items()
    ke_ref = np.mean([r["ke"] for r in ref_runs], axis=0)
    scale = float(ke_ref.max())
    floor = None
    if len(ref_runs) > 1:  # two realizations of a chaotic fall: their difference / sqrt 2
        floor = float(np.max(np.abs(np.array(ref_runs[0]["ke"]) - ref_runs[1]["ke"]))
                      / math.sqrt(2) / scale)
    rows = []
    speed = _by_label(runs, results, "dish/speed")
    for label, rs in {**speed, **refs}.items():
        ke = np.mean([r["ke"] for r in rs], axis=0)
        err = float(np.max(np.abs(ke - ke_ref))) / scale
        fails = {k: v for r in rs for k, v in (r.get("failures") or {}).items()}
        obs = rs[0].get("observables") or {}
        note = (f"bed height {1e3 * obs['bed_height']:.2f} mm, packing fraction "
                f"{obs['packing_fraction']:.3f}; "
                if obs.get("bed_height") is not None and obs.get("packing_fraction") is not None
                else "")
        note += f"floor carries {rs[0]['floor_load']:.3f} of the weight"
        if fails:
            note += f"; failures: {fails}"
        if label == ref_label:
            note = "reference; " + note
        seq = speed.get(label.split(" graph")[0].split(" grid")[0])
        if "threads" in label and seq:
            same = [a.get("state_hash") == b.get("state_hash") for a, b in zip(rs, seq)]
            note = ("final state bitwise identical to the sequential run; " if all(same)
                    else "final state DIFFERS from the sequential run; ") + note
        rows.append({"scene": "dish", "method": label, "family": _family(label),
                     "reference": label == ref_label,
                     "setting": _setting(label), "wall_s": float(sum(r["wall_s"] for r in rs)),
                     "error": err, "seeds": len(rs), "n": rs[0]["n"], "note": note,
                     "settle_time": _mean_finite([r["settle_time"] for r in rs])})
    return rows, floor


def marble_rows(runs, results):
    """(rows, None) of the marble drop."""
    refs = _by_label(runs, results, "dish_marble/reference")
    if not refs:
        return [], None
    (ref_label, (ref,)), = refs.items()
    d = ref["grain_diameter"]
    rows = []
    speed = _by_label(runs, results, "dish_marble/speed")
    for label, (r,) in {**speed, **refs}.items():
        note = (f"depth {1e3 * r['depth']:.2f} mm, at rest after "
                f"{r['rest_time'] * 1e3:.0f} ms" if r["rest_time"] is not None and
                math.isfinite(r["rest_time"]) else f"depth {1e3 * r['depth']:.2f} mm, not at rest")
        if r.get("failures"):
            note += f"; failures: {r['failures']}"
        seq = speed.get(label.split(" graph")[0].split(" grid")[0])
        if "threads" in label and seq:
            same = (r["trajectory"] == seq[0]["trajectory"]
                    and r.get("state_hash") == seq[0].get("state_hash"))
            note = ("final state bitwise identical to the sequential run; " if same
                    else "final state DIFFERS from the sequential run; ") + note
            note += (f"; {r.get('violations', 0)} causality violations detected, "
                     f"{r.get('repairs', 0)} steps repaired")
        rows.append({"scene": "dish_marble", "method": label, "family": _family(label),
                     "reference": label == ref_label,
                     "setting": _setting(label), "wall_s": r["wall_s"],
                     "error": abs(r["depth"] - ref["depth"]) / d, "n": r["n"],
                     "note": ("reference; " if label == ref_label else "") + note})
    return rows, None


def table_rows(scene, runs, results, p=16):
    """Rows of the paper's table for ``scene`` (one per lock configuration) and
    the raw per-state results."""
    by_state = {}
    for r in runs:
        res = results.get(r.key)
        if r.group == f"tables/{scene}" and res is not None and "failed" not in res:
            by_state[r.params["state"]] = res
    rows = []
    for k, key in enumerate(LOCKS):
        name = key_name(key)
        row = {"scene": scene, "lock": name}
        for state in ("early", "late"):
            res = by_state.get(state)
            grid = res["locks"]["grid"]["replay"][f"exact/{p}"]["time_s"] if res else None
            rec = res["locks"][name] if res else None
            rep = rec["replay"][f"exact/{p}"] if rec else None
            paper = PAPER[scene][state][k]
            paper_grid = PAPER[scene][state][-1]
            row.update({
                f"{state}_n": res["n"] if res else None,
                f"{state}_measured2_ms": rec["par2_events_s"] * 1e3 if rec else None,
                f"{state}_replay_ms": rep["time_s"] * 1e3 if rep else None,
                f"{state}_replay_over_grid": (rep["time_s"] / grid if rep and grid else None),
                f"{state}_concurrency": rep["concurrency_events_only"] if rep else None,
                f"{state}_repairs": rec["repairs"] if rec else None,
                f"{state}_paper_s": paper if math.isfinite(paper) else None,
                f"{state}_paper_over_grid": (paper / paper_grid if math.isfinite(paper)
                                             and math.isfinite(paper_grid) else None)})
        rows.append(row)
    return rows, by_state

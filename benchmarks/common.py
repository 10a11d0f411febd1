"""Helpers shared by the benchmark scripts."""
import csv
import math
import os

import numpy as np


def write_csv(rows, path):
    """Write a list of dicts as CSV atomically: never a half-written file."""
    with open(path + ".tmp", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(path + ".tmp", path)


def cached_npz(path, make):
    """``make()``'s dict of arrays and numbers, from the .npz file ``path`` if
    it exists, else made and written there whole (an interrupted run leaves
    none).  Returns (dict, whether it came from the file)."""
    if os.path.exists(path):
        with np.load(path) as f:
            return {k: (f[k] if f[k].ndim else float(f[k])) for k in f.files}, True
    os.makedirs(os.path.dirname(path) or ".", exist_ok=True)
    res = make()
    tmp = path + ".tmp.npz"
    np.savez(tmp, **res)
    os.replace(tmp, path)
    return res, False


def noise_floor(values):
    """How far two methods' means over k seeds differ with no method error
    (the runs are chaotic): sqrt(2 / k) times the standard deviation of one
    run's value, estimated from the reference's k seeds (``values``, one per
    seed; a leading axis of arrays: the largest over the rest)."""
    values = np.asarray(values, float)
    k = values.shape[0]
    return float(np.max(np.std(values, axis=0, ddof=1))) * math.sqrt(2 / k)


def chart(rows, err_key, xlabel, title, png, floor=None, smallest=1e-4, wall_key="wall_s",
          ylabel="wall time (s)"):
    """Wall time (``wall_key``) against error, one series per ``family``, each
    point labelled by its method; written atomically to ``png``.  Errors below
    ``smallest`` (the reference's zero) are drawn at it; rows whose wall time
    or error is NaN are left out.  Returns False without matplotlib."""
    rows = [r for r in rows if r[wall_key] == r[wall_key] and r[err_key] == r[err_key]]
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib missing: no chart")
        return False
    fig, ax = plt.subplots(figsize=(6.5, 4.5))
    for fam in dict.fromkeys(r["family"] for r in rows):
        sel = [r for r in rows if r["family"] == fam]
        xs = [max(r[err_key], smallest) for r in sel]
        ax.plot(xs, [r[wall_key] for r in sel], "o-", label=fam)
        for x, r in zip(xs, sel):
            ax.annotate(r["method"].split(" ", 1)[1] if " " in r["method"] else "",
                        (x, r[wall_key]), fontsize=6)
    if floor is not None:
        ax.axvline(floor, color="grey", ls=":", label="noise floor")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(png + ".tmp.png", dpi=120)
    os.replace(png + ".tmp.png", png)
    plt.close(fig)
    return True

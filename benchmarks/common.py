"""Helpers shared by the benchmark scripts."""
import csv
import os


def write_csv(rows, path):
    """Write a list of dicts as CSV atomically: never a half-written file."""
    with open(path + ".tmp", "w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=list(rows[0]))
        w.writeheader()
        w.writerows(rows)
    os.replace(path + ".tmp", path)


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

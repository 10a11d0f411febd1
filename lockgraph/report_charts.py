"""The report's charts: PNG files written atomically (matplotlib, Agg).

Each function takes plain rows (dicts) computed by ``report_tables`` and a
path, and returns the path written.
"""
import os

FAMILY_STYLE = {"lockgraph": ("C0", "o"), "lockgraph 2 threads": ("C2", "^"),
                "REBOUND": ("C3", "s"), "LAMMPS": ("C1", "D"), "LAMMPS 2 ranks": ("C5", "v"),
                "LIGGGHTS": ("C4", "P")}


def pyplot():
    """matplotlib.pyplot on the Agg backend (no display needed)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def save(fig, path):
    """Write ``fig`` to ``path`` whole (a temporary file renamed); returns path."""
    plt = pyplot()
    fig.tight_layout()
    tmp = path + ".tmp.png"
    fig.savefig(tmp, dpi=100)
    plt.close(fig)
    os.replace(tmp, path)
    return path


def pareto(rows, x="error", y="wall_s"):
    """The rows no other row beats in both ``x`` and ``y`` (lower is better),
    ordered by ``y``."""
    pts = sorted((r for r in rows if r[x] is not None and r[y] is not None),
                 key=lambda r: (r[y], r[x]))
    front, best = [], float("inf")
    for r in pts:
        if r[x] < best:
            front.append(r)
            best = r[x]
    return front


def speed_accuracy(rows, path, title, xlabel, floor=None, smallest=1e-4):
    """Wall time against error, one series per method family, the Pareto
    front dashed.  Errors below ``smallest`` are drawn at it."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(7.0, 4.6))
    refs = [r for r in rows if r.get("reference")]
    rows = [r for r in rows if not r.get("reference")]
    for r in refs:  # the reference defines zero error: a star on the left edge
        ax.plot([smallest], [r["wall_s"]], marker="*", ms=12, color="k", ls="none",
                label=f"reference ({r['setting']})")
    for fam in dict.fromkeys(r["family"] for r in rows):
        sel = [r for r in rows if r["family"] == fam and r["error"] is not None]
        colour, marker = FAMILY_STYLE.get(fam, ("k", "x"))
        ax.plot([max(r["error"], smallest) for r in sel], [r["wall_s"] for r in sel],
                marker=marker, color=colour, ls="none", label=fam)
        for r in sel:
            ax.annotate(r["setting"], (max(r["error"], smallest), r["wall_s"]), fontsize=6,
                        textcoords="offset points", xytext=(3, 3))
    front = pareto([r for r in rows if r["error"] is not None])
    if front:
        ax.step([max(r["error"], smallest) for r in front], [r["wall_s"] for r in front],
                where="post", color="grey", ls="--", lw=1, label="Pareto front")
    if floor:
        ax.axvline(floor, color="grey", ls=":", label="noise floor")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel("wall time (s)")
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7)
    return save(fig, path)


def replay_curves(table, path, title):
    """Replayed events-phase time against thread count P for each lock
    configuration (late state if present), with the measured 2-thread point."""
    plt = pyplot()
    fig, axes = plt.subplots(1, len(table), figsize=(5.2 * len(table), 3.8), squeeze=False)
    for ax, (state, res) in zip(axes[0], table.items()):
        for name, rec in res["locks"].items():
            ps = sorted({int(k.split("/")[1]) for k in rec["replay"]})
            ts = [rec["replay"][f"exact/{p}"]["time_s"] * 1e3 for p in ps]
            line, = ax.plot(ps, ts, marker=".", label=name)
            ax.plot([2], [rec["par2_events_s"] * 1e3], marker="*", ms=10, ls="none",
                    color=line.get_color())
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xlabel("threads P (replay; stars: measured, 2 threads)")
        ax.set_ylabel("events phase (ms)")
        ax.set_title(f"{title}, {state} (N = {res['n']})", fontsize=9)
        ax.legend(fontsize=6)
    return save(fig, path)


def series(curves, path, title, xlabel, ylabel, logy=False):
    """Plain lines: ``curves`` is [(label, xs, ys)]."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    for label, xs, ys in curves:
        ax.plot(xs, ys, label=label, lw=1)
    if logy:
        ax.set_yscale("log")
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    ax.legend(fontsize=7)
    return save(fig, path)


def bars(labels, values, path, title, ylabel, logy=False):
    """One bar per label."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(6.0, 3.8))
    ax.bar(range(len(values)), [v if v is not None else 0.0 for v in values], color="C0")
    ax.set_xticks(range(len(values)))
    ax.set_xticklabels(labels, rotation=30, ha="right", fontsize=7)
    if logy:
        ax.set_yscale("log")
    ax.set_ylabel(ylabel)
    ax.set_title(title, fontsize=10)
    return save(fig, path)

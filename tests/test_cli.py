"""The command line: JSON fields, parameter overrides, saving, exit codes."""
import json
import os
import subprocess
import sys

import numpy as np

from lockgraph import _jit
from lockgraph.cli import main

REQUIRED = ["scene", "state", "n", "steps", "threads", "lock", "scale", "collisions",
            "guarded_impacts", "wall_s", "phase_s",
            "compile_s", "events_per_s", "max_overlap", "violations", "state_sha256",
            "peak_rss_mb"]


def run_json(capsys, *args):
    code = main(["run", *args, "--json", "--quiet"])
    out = capsys.readouterr()
    assert code == 0, out.err
    return json.loads(out.out)


def test_json_fields(capsys):
    d = run_json(capsys, "gas", "--n", "256", "--steps", "5")
    for k in REQUIRED + ["pressure_reduced"]:
        assert k in d, k
    assert d["scene"] == "gas" and d["n"] == 256 and d["steps"] == 5
    assert d["collisions"] > 0 and d["max_overlap"] < 1e-12 and d["violations"] == 0
    # the phases split the steps' time, which the run's wall time encloses
    ph = d["phase_s"]
    assert set(ph) == {"search", "events", "other", "step"}
    assert min(ph.values()) >= 0.0 and 0.0 < ph["step"] <= d["wall_s"]


def test_param_override(capsys):
    a = run_json(capsys, "gas", "--n", "256", "--steps", "2", "--param", "eta=0.40")
    b = run_json(capsys, "gas", "--n", "256", "--steps", "2")
    assert a["params"]["eta"] == 0.40 and b["params"]["eta"] == 0.45
    assert a["state_sha256"] != b["state_sha256"]


def test_save_orders_by_id(tmp_path, capsys):
    path = tmp_path / "out.npz"
    d = run_json(capsys, "ring", "--n", "300", "--steps", "5", "--save", str(path))
    with np.load(path) as f:
        import hashlib
        h = hashlib.sha256(f["pos"].tobytes() + f["vel"].tobytes()).hexdigest()
        assert h == d["state_sha256"]
        assert f["radius"].shape == (300,) and f["mass"].shape == (300,)


def test_bad_input_exit_code(capsys):
    assert main(["run", "gas", "--param", "etta=0.3", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "params.etta" in err and "unknown scenario key" in err
    assert main(["run", "gas", "--dt", "-1", "--quiet"]) == 2
    assert "params.dt" in capsys.readouterr().err
    assert main(["run", "gas", "--lock", "tree", "--quiet"]) == 2
    assert "lock" in capsys.readouterr().err


COLLAPSING = """
name = "collapsing"
generator = "grain_block"
late = "settle"
[physics]
domain = "dish"
forces = ["gravity"]
restitution = "constant"
collapse_guard = false
[params]
n = 20
seed = 1
grain_radius = 5.0e-4
grain_density = 2330.0
cylinder_radius = 0.003
spacing = 1.5
jitter = 0.5
drop_height = 0.0005
velocity_jitter = 0.0
g = 9.81
e = 0.5
dt = 0.01
settle_speed = 0.005
settle_time_max = 1.0
"""


def test_failed_run_never_overwrites_saved_state(tmp_path, capsys):
    scene = tmp_path / "collapsing.toml"
    scene.write_text(COLLAPSING)
    path = tmp_path / "state.npz"
    path.write_bytes(b"precious")
    code = main(["run", str(scene), "--steps", "200", "--save", str(path), "--quiet"])
    err = capsys.readouterr().err
    assert code == 3, err
    assert "inelastic collapse" in err
    assert path.read_bytes() == b"precious"


def test_console_script_progress():
    """The installed entry point runs and reports progress on stderr."""
    exe = os.path.join(os.path.dirname(sys.executable), "lockgraph")
    p = subprocess.run([exe, "run", "gas", "--n", "256", "--steps", "3"], capture_output=True,
                       text=True, timeout=300, env=_jit.child_env())
    assert p.returncode == 0, p.stderr
    assert "step 3/3" in p.stderr
    assert "state_sha256" in p.stdout


def test_scenes_listing(capsys):
    assert main(["scenes"]) == 0
    out = capsys.readouterr().out
    for name in ("ring", "ring_moonlet", "dish", "dish_marble", "gas"):
        assert name in out


def test_threads_json_reports_parallel_statistics(capsys):
    one = run_json(capsys, "ring", "--n", "600", "--steps", "6", "--param", "dispersion=0.003",
                   "--param", "dt=60")
    two = run_json(capsys, "ring", "--n", "600", "--steps", "6", "--param", "dispersion=0.003",
                   "--param", "dt=60", "--threads", "2", "--lock", "graph", "--scale", "2",
                   "--policy", "exact")
    assert two["state_sha256"] == one["state_sha256"]
    for k in ("events", "mean_concurrency", "blocked_picks", "violations", "repairs",
              "repairs_on_threads", "wait_s"):
        assert k in two
    assert two["repairs_on_threads"] == 0  # only pool steps are redone on the threads
    assert two["threads"] == 2 and two["lock"] == "graph" and two["scale"] == 2.0
    assert two["stats"]["locks"]["regions"] >= 1
    assert two["schedule"] == "parallel" and two["threaded_event_steps"] == 6
    auto = run_json(capsys, "ring", "--n", "600", "--steps", "6", "--param", "dispersion=0.003",
                    "--param", "dt=60", "--threads", "2", "--schedule", "auto")
    assert auto["state_sha256"] == one["state_sha256"]
    # each way is measured before any choice: at least one step on the threads
    # and one on one thread
    assert auto["schedule"] == "auto" and 1 <= auto["threaded_event_steps"] <= 5

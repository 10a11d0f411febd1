"""``benchmarks/target_runs.py``: the tally of the 2-thread target, run after
run.  The counts are checked on made-up rows (exact); one small real run
checks that a run's JSON from ``parallel_speedup.py`` reaches the tally."""
import math

import pytest


def row(case, best, ceiling, over=1.0, identical=True):
    return {"file": f"{case}.json", "case": case, "engine": "pool", "n": 1, "best": best,
            "paired": best, "ceiling_best": ceiling, "ceiling_paired": ceiling,
            "over_ceiling": over, "identical": identical}


def test_reached_counts_to_two_decimals(load_benchmark):
    tr = load_benchmark("target_runs")
    # the README counts a run printed as 1.70x as reaching 1.7x
    assert tr.reached(1.6951) and tr.reached(1.7) and tr.reached(2.0)
    assert not tr.reached(1.6949) and not tr.reached(1.5)


def test_tally_counts_runs_and_ceilings(load_benchmark):
    tr = load_benchmark("target_runs")
    rows = [row("ring", 1.78, 1.95, 0.97), row("ring", 1.66, 1.65, 1.01),
            row("ring", 1.69, 1.85, 0.93), row("bed", 1.52, 1.71, 0.97, identical=False)]
    t = tr.tally(rows)
    assert set(t) == {"ring", "bed"}
    ring = t["ring"]
    assert ring["runs"] == 3 and ring["reached"] == 1
    assert ring["best_range"] == (1.66, 1.78)
    # two ceilings at 1.7x or more (1.95, 1.85); the engine reached the target under one
    assert ring["ceiling_reached"] == 2 and ring["reached_under_able_ceiling"] == 1
    assert ring["over_ceiling_median"] == 0.97
    assert ring["over_ceiling_range"] == (0.93, 1.01)
    assert ring["all_identical"]
    bed = t["bed"]
    assert bed["runs"] == 1 and bed["reached"] == 0 and bed["ceiling_reached"] == 1
    assert not bed["all_identical"]


def test_a_small_run_reaches_the_tally(load_benchmark, tmp_path, capsys):
    tr = load_benchmark("target_runs")
    # the target command on a small ring: one step, one repeat (a fresh process)
    assert tr.main(["--cases", "ring", "--runs", "1", "--repeats", "1", "--steps", "1",
                    "--n", "ring=3000", "--dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["target_ring_1.json", "target_ring_1.log"]
    r, = tr.run_record(tmp_path / "target_ring_1.json")
    assert r["case"] == "ring" and r["n"] == 3000 and r["engine"] == "2 threads pool 16 domains"
    assert r["identical"]  # the exact policy's guarantee, checked in every run
    assert r["best"] > 0 and math.isfinite(r["ceiling_best"])
    assert "ring: the engine reached 1.7x best over best in" in out
    # and the tally alone, from the folder
    assert tr.main(["--tally", str(tmp_path)]) == 0
    assert "target_ring_1.json" in capsys.readouterr().out


def test_bad_options_are_refused(load_benchmark, tmp_path):
    tr = load_benchmark("target_runs")
    with pytest.raises(SystemExit):
        tr.main(["--cases", "gas"])
    with pytest.raises(SystemExit):
        tr.main(["--tally", str(tmp_path)])  # no JSON there
    with pytest.raises(SystemExit):
        tr.main(["--runs", "0"])

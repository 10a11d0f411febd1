"""The report's campaign machinery: run keys, the on-disk cache (whole files
only, failed runs never cached), progress output, and the plan's input checks."""
import io
import json
import os

import pytest

from lockgraph import campaign, report_plan, report_runs
from lockgraph.campaign import Cache, Run, run_campaign
from lockgraph.cli import main
from lockgraph.errors import InputError


def square(x, progress):
    progress(0.5, "half")
    if x < 0:
        raise ValueError("x must be >= 0")
    return {"wall_s": 0.0, "y": x * x}


@pytest.fixture
def kinds(monkeypatch):
    """A cheap kind beside the real ones, so the machinery runs in milliseconds."""
    monkeypatch.setitem(report_runs.KINDS, "square", square)


class TestRun:
    def test_key_depends_on_kind_and_params_only(self):
        a = Run("square", {"x": 2, "y": [1, 2]}, "a", "g1")
        b = Run("square", {"y": [1, 2], "x": 2}, "b", "g2")
        assert a.key == b.key  # labels, groups and key order do not matter
        assert Run("square", {"x": 3}).key != Run("square", {"x": 2}).key
        assert Run("cube", {"x": 2}).key != Run("square", {"x": 2}).key

    def test_key_changes_with_the_cache_version(self, monkeypatch):
        k = Run("square", {"x": 2}).key
        monkeypatch.setattr(campaign, "CACHE_VERSION", campaign.CACHE_VERSION + 1)
        assert Run("square", {"x": 2}).key != k


class TestCampaign:
    def test_results_are_cached_and_reused(self, kinds, tmp_path):
        cache = Cache(tmp_path)
        runs = [Run("square", {"x": x}, f"x={x}") for x in (1, 2, 3)]
        err = io.StringIO()
        res = run_campaign(runs, cache, stream=err)
        assert [res[r.key]["y"] for r in runs] == [1, 4, 9]
        assert "3 runs, 0 from the cache (" in err.getvalue()
        assert sorted(os.listdir(tmp_path)) == sorted(r.key + ".json" for r in runs)
        on_disk = json.loads((tmp_path / (runs[1].key + ".json")).read_text())
        assert on_disk["params"] == {"x": 2} and on_disk["result"]["y"] == 4
        err = io.StringIO()
        assert run_campaign(runs, cache, stream=err) == res
        assert "3 runs, 3 from the cache" in err.getvalue()

    def test_a_failed_run_is_reported_not_cached(self, kinds, tmp_path):
        cache = Cache(tmp_path)
        bad, good = Run("square", {"x": -1}, "bad"), Run("square", {"x": 2}, "good")
        err = io.StringIO()
        res = run_campaign([bad, good], cache, stream=err)
        assert res[bad.key]["failed"] == "ValueError: x must be >= 0"
        assert res[good.key]["y"] == 4
        assert "bad: FAILED (ValueError: x must be >= 0)" in err.getvalue()
        assert cache.get(bad) is None and cache.get(good)["y"] == 4

    def test_duplicates_run_once(self, kinds, tmp_path):
        runs = [Run("square", {"x": 2}, "a", "g1"), Run("square", {"x": 2}, "b", "g2")]
        err = io.StringIO()
        run_campaign(runs, Cache(tmp_path), stream=err)
        assert "2 runs, 0 from the cache" in err.getvalue() and "1 to run" in err.getvalue()

    def test_torn_and_stale_files_are_ignored(self, kinds, tmp_path):
        run = Run("square", {"x": 2})
        (tmp_path / (run.key + ".json")).write_text('{"result": {"y"')  # torn write
        (tmp_path / (run.key + ".json.999999999.tmp")).write_text("{")  # dead writer
        cache = Cache(tmp_path)
        assert cache.get(run) is None
        assert not list(tmp_path.glob("*.tmp"))
        run_campaign([run], cache, stream=io.StringIO())
        assert cache.get(run)["y"] == 4

    def test_progress_bars(self, kinds, tmp_path):
        err = io.StringIO()
        run_campaign([Run("square", {"x": 1}, "one")], Cache(tmp_path), stream=err, every=0.0)
        text = err.getvalue()
        assert "0/1 runs" in text and "one [" in text and "50%" in text
        assert "1/1 runs" in text and "one: done" in text


class TestPlan:
    @pytest.mark.parametrize("mode", report_plan.MODES)
    def test_every_scene_has_speed_reference_and_tables(self, mode):
        runs = report_plan.plan(mode)
        groups = {r.group for r in runs}
        for s in report_plan.SCENES:
            assert {f"{s}/speed", f"{s}/reference", f"tables/{s}"} <= groups
        assert "failures" in groups
        assert all(r.kind in report_runs.KINDS for r in runs)
        json.dumps([r.params for r in runs])  # parameters are JSON: they key the cache

    def test_bad_mode_and_scene_name_the_field(self):
        with pytest.raises(InputError, match="mode"):
            report_plan.plan("fast")
        with pytest.raises(InputError, match="scenes: unknown scene 'moon'"):
            report_plan.plan("quick", ["ring", "moon"])

    def test_cli_rejects_an_unknown_scene(self, tmp_path, capsys):
        assert main(["report", "--scenes", "ring,moon", "--out", str(tmp_path)]) == 2
        assert "scenes: unknown scene 'moon'" in capsys.readouterr().err

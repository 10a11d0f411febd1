"""The speed benchmark's rounds (``benchmarks/parallel_speedup.py``,
``run_case``): the engines take each step in turn, and the host probe runs
once a round, after the engines' steps, never just before one (a probe just
before the 2-thread engine's step slowed that step by 4-8 %: README,
Benchmarks, "The host probe after the steps")."""
import pytest


@pytest.fixture(scope="module")
def ps(load_benchmark):
    return load_benchmark("parallel_speedup")


def test_the_probe_runs_once_a_round_after_the_engines_steps(ps, monkeypatch, capsys):
    calls = []  # ("step", threads) and ("probe",), in order

    class Probe:  # the real probe's answer shape: (chain, gather, alu, handoff ns)
        def measure(self):
            calls.append(("probe",))
            return (2.0, 2.0, 2.0, 100.0)

        def close(self):
            pass

    step = ps.Engine.step

    def counted(self, *args, **kwargs):
        calls.append(("step", self.threads))
        return step(self, *args, **kwargs)

    monkeypatch.setattr(ps, "TwoCoreProbe", Probe)
    monkeypatch.setattr(ps.Engine, "step", counted)
    steps, repeats = 3, 2
    res = ps.run_case("ring", "ring", "early", 1500, steps, repeats, ps.parse_locks("pool:4"),
                      ceiling="none")
    assert all(r["identical"] for r in res["runs"].values())
    # the untimed first step of each engine, then rounds of (sequential step,
    # 2-thread step, probe)
    warm = [("step", 1), ("step", 2)]
    assert calls == warm + [("step", 1), ("step", 2), ("probe",)] * (steps * repeats)
    # one probe record a step of each engine, the round's
    pr = res["host_two_core_probes"]
    assert len(pr) == 2 * steps * repeats
    assert pr[0::2] == pr[1::2]
    # and the report counts each round's probe once
    ps.print_case("ring", res)
    assert f"two cores in {steps * repeats} of {steps * repeats} probes" in capsys.readouterr().out

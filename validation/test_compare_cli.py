"""``lockgraph compare`` against REBOUND: the JSON report's shape and its errors."""
import json

from lockgraph.cli import main

OBSERVABLES = ("sigma_x", "sigma_y", "sigma_z", "thickness", "tau", "filling_midplane",
               "nu_trans", "collision_rate", "nu_coll")


def test_compare_json_report(rebound, capsys):
    code = main(["compare", "ring", "--against", "rebound", "--n", "400", "--orbits", "0.2",
                 "--seeds", "2", "--dt-orbits", "2e-3", "--json", "--quiet"])
    assert code == 0
    res = json.loads(capsys.readouterr().out)
    assert set(OBSERVABLES) <= set(res["observables"])
    for o in res["observables"].values():
        for key in ("lockgraph", "reference", "uncertainty", "z", "agree", "unit"):
            assert key in o
    assert isinstance(res["agree"], bool)
    assert res["wall_s"]["lockgraph"] > 0 and res["wall_s"]["reference"] > 0
    for key in ("overlaps", "max_overlap", "missed_collisions", "lost_particles"):
        assert key in res["reference_failures"]
    assert res["lockgraph_failures"]["max_overlap"] < 1e-12
    assert res["seeds"] == [1, 2] and res["reference_settings"]["dt_orbits"] == 2e-3


def test_compare_bad_input(capsys):
    assert main(["compare", "ring", "--against", "gadget", "--quiet"]) == 2
    assert "against" in capsys.readouterr().err
    assert main(["compare", "ring", "--against", "rebound", "--seeds", "1", "--quiet"]) == 2
    assert "seeds" in capsys.readouterr().err
    assert main(["compare", "dish", "--against", "rebound", "--quiet"]) == 2
    assert "scene" in capsys.readouterr().err


def test_compare_table_and_out_file(rebound, capsys, tmp_path):
    out = tmp_path / "ring.json"
    code = main(["compare", "ring", "--against", "rebound", "--n", "400", "--orbits", "0.2",
                 "--seeds", "2", "--quiet", "--out", str(out)])
    assert code == 0
    text = capsys.readouterr().out
    for word in ("sigma_x", "nu_coll", "agree:", "collisions: lockgraph", "REBOUND:"):
        assert word in text
    res = json.loads(out.read_text())
    assert res["against"] == "rebound" and not (tmp_path / "ring.json.tmp").exists()


def test_compare_dish_against_lammps_cli(lammps_lmp, tmp_path, capsys):
    """The DEM comparison from the command line: a small, short dish (the JSON
    shape is that of the REBOUND comparison)."""
    import json

    from lockgraph.cli import main

    out = tmp_path / "dish.json"
    code = main(["compare", "dish", "--against", "lammps", "--n", "200", "--time", "0.2",
                 "--seeds", "2", "--param", "cylinder_radius=0.004", "--out", str(out),
                 "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    assert "LAMMPS" in text and "packing_fraction" in text and "floor load" in text
    res = json.loads(out.read_text())
    assert res["against"] == "lammps" and res["n"] == 200 and res["seeds"] == [1, 2]
    assert set(res["observables"]) == {"bed_height", "packing_fraction", "floor_coverage",
                                       "wall_coverage"}
    for o in res["observables"].values():
        assert {"lockgraph", "reference", "uncertainty", "z", "agree"} <= set(o)
    assert res["reference_settings"]["code"].startswith("LAMMPS")
    assert res["wall_s"]["reference"] > 0


def test_compare_unknown_code_names_the_field(capsys):
    from lockgraph.cli import main

    assert main(["compare", "dish", "--against", "yade", "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "against" in err and "lammps" in err and "liggghts" in err
    # the DEM codes compare the dish only
    assert main(["compare", "ring", "--against", "lammps", "--quiet"]) == 2
    assert "scene" in capsys.readouterr().err


def test_compare_dish_marble_cli(lammps_lmp, tmp_path, capsys, monkeypatch):
    """The marble comparison from the command line, small: 200 grains, one drop."""
    import json

    from lockgraph.cli import main

    monkeypatch.setenv("LOCKGRAPH_CACHE", str(tmp_path / "cache"))
    out = tmp_path / "marble.json"
    code = main(["compare", "dish_marble", "--against", "lammps", "--n", "201", "--seeds", "1",
                 "--heights", "0.02", "--time", "0.05", "--param", "cylinder_radius=0.003",
                 "--param", "marble_radius=0.001", "--out", str(out), "--quiet"])
    assert code == 0
    text = capsys.readouterr().out
    assert "depth lockgraph" in text and "LAMMPS" in text
    res = json.loads(out.read_text())
    assert res["against"] == "lammps" and res["heights"] == [0.02]
    (o,) = res["per_height"]
    assert o["lockgraph"]["depth"] > 0 and o["reference"]["depth"] > 0
    assert main(["compare", "dish_marble", "--against", "lammps", "--heights", "-1",
                 "--quiet"]) == 2
    assert "heights" in capsys.readouterr().err

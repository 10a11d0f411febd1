"""Scene pictures: PNG files written whole, and the lock graph drawn is the
engine's (regions and adjacencies counted independently from its trace)."""
import numpy as np
import pytest

from lockgraph import pictures, scenarios
from lockgraph.engine import Engine

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"

# (scene, n, SCALE): at N = 301 the marble makes the whole dish one region at
# SCALE 4 (no edges to check); SCALE 2 splits it into ~17 around the marble's
SCENES = [("ring", 300, 4.0), ("dish_marble", 301, 2.0)]


@pytest.fixture(scope="module", params=SCENES, ids=lambda p: p[0])
def case(request):
    name, n, scale = request.param
    return scenarios.load(name, "early", n=n), scale


def engine_graph(sc, scale):
    """(region of each particle id, loff, ladj) straight from an engine's trace."""
    eng = Engine(sc.state, sc.physics, sc.dt, trace_locks=[("graph", scale)])
    eng.step()
    steps = eng.trace()["steps"]
    assert len(steps) == 1 and list(steps[0]["locks"]) == [("graph", scale)]
    return steps[0]["locks"][("graph", scale)]


def assert_png(path, tmp_path):
    data = open(path, "rb").read()
    assert data[:8] == PNG_MAGIC and len(data) > 2000
    assert not list(tmp_path.glob("*.tmp.png"))  # the temporary was renamed


class TestPictures:
    def test_snapshot_is_a_png(self, case, tmp_path):
        sc, _ = case
        path = str(tmp_path / "snap.png")
        assert pictures.scene_snapshot(sc, path, "title") == path
        assert_png(path, tmp_path)

    def test_lock_graph_matches_the_engine(self, case, tmp_path):
        sc, scale = case
        path = tmp_path / "lg.png"
        info = pictures.lock_graph_figure(sc, str(path), scale)
        assert_png(path, tmp_path)
        by_id, loff, ladj = engine_graph(sc, scale)
        nreg = loff.size - 1
        assert by_id.shape == (sc.state.n,) and loff[0] == 0 and loff[-1] == ladj.size
        # lock-graph regions are kD-tree nodes: every one holds particles, so
        # "occupied regions" (what is drawn) is all of them
        assert np.array_equal(np.unique(by_id), np.arange(nreg))
        pairs = {(a, int(b)) for a in range(nreg) for b in ladj[loff[a]:loff[a + 1]]}
        assert len(pairs) == ladj.size                 # no repeated neighbour
        assert all((b, a) in pairs for a, b in pairs)  # adjacency is symmetric
        assert all(a != b for a, b in pairs)           # and has no self loops
        assert nreg > 1 and ladj.size > 0              # a graph worth checking
        assert info == {"regions": nreg, "edges": ladj.size // 2,
                        "particles": sc.state.n, "scale": scale}

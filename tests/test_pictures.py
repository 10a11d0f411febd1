"""Scene pictures: PNG files written whole, and the lock graph drawn is the
engine's (regions and adjacencies counted independently from its trace)."""
import numpy as np
import pytest

from lockgraph import pictures, scenarios

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module", params=[("ring", "early", 600), ("dish_marble", "early", 301)],
                ids=lambda p: p[0])
def scene(request):
    name, state, n = request.param
    return scenarios.load(name, state, n=n)


class TestPictures:
    def test_snapshot_is_a_png(self, scene, tmp_path):
        path = pictures.scene_snapshot(scene, str(tmp_path / "snap.png"), "title")
        data = open(path, "rb").read()
        assert data[:8] == PNG_MAGIC and len(data) > 2000
        assert [p.name for p in tmp_path.iterdir()] == ["snap.png"]  # no temporary left

    def test_lock_graph_matches_the_engine(self, scene, tmp_path):
        info = pictures.lock_graph_figure(scene, str(tmp_path / "lg.png"), 4.0)
        assert open(tmp_path / "lg.png", "rb").read(8) == PNG_MAGIC
        by_id, loff, ladj = pictures.lock_regions(scene, 4.0)
        assert by_id.shape == (scene.state.n,)
        used = np.zeros(loff.size - 1, bool)
        used[by_id] = True
        pairs = {(a, int(b)) for a in range(loff.size - 1) for b in ladj[loff[a]:loff[a + 1]]}
        assert all((b, a) in pairs for a, b in pairs)  # adjacency is symmetric
        assert all(a != b for a, b in pairs)           # and has no self loops
        drawn = {(a, b) for a, b in pairs if a < b and used[a] and used[b]}
        assert info == {"regions": int(used.sum()), "edges": len(drawn),
                        "particles": scene.state.n, "scale": 4.0}

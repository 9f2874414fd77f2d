"""Map-pair dataset files: round trip, atomic writes, corrupt and foreign files."""

import json

import numpy as np
import pytest

from fusion import Rigid2D
from fusion.evaluation.pairs import (
    DatasetError,
    GridSnapshot,
    MapPair,
    load_pairs,
    pair_files,
    pair_path,
    read_pair,
    write_index,
    write_pair,
)
from topo import TopoMap
from topo.fileio import atomic_write_json


def make_pair(pair_id: int, rng: np.random.Generator, with_paths: bool = True) -> MapPair:
    xy = rng.uniform(-5, 5, (6, 2))
    edges = np.array([[0, 1], [1, 2], [1, 3], [3, 4], [4, 5]])
    paths = [np.array([xy[u], (xy[u] + xy[v]) / 2, xy[v]]) for u, v in edges] if with_paths else None
    truth = Rigid2D(rng.uniform(-np.pi, np.pi), rng.uniform(-3, 3, 2))
    map_a = TopoMap.from_arrays(xy, edges, paths=paths)
    map_b = TopoMap.from_arrays(truth.inverse().apply(xy[:4]), edges[:3])
    grid = GridSnapshot(rng.integers(0, 3, (40, 30)).astype(np.int8), 0.1, (-1.5, -2.0))
    return MapPair(pair_id, map_a, map_b, grid, grid, truth, 0.4, "procedural:7", 123,
                   "frontier", 250, pair_id // 3, pair_id % 3, {"coverage": 0.5})


def new_dataset(tmp_path):
    atomic_write_json(tmp_path / "dataset.json", {"format": "topomerge.map_pairs", "version": 1})
    return tmp_path


@pytest.mark.parametrize("with_paths", [True, False])
def test_round_trip_keeps_everything(tmp_path, with_paths):
    root = new_dataset(tmp_path)
    rng = np.random.default_rng(0)
    pairs = [make_pair(i, rng, with_paths) for i in range(4)]
    for p in pairs:
        write_pair(root, p)
    back = load_pairs(root)
    assert [p.pair_id for p in back] == [0, 1, 2, 3]
    for p, q in zip(pairs, back, strict=True):
        assert q.map_a.equals(p.map_a) and q.map_b.equals(p.map_b)
        assert (q.map_a.paths is None) == (not with_paths)
        assert q.transform.allclose(p.transform, atol=1e-12)
        np.testing.assert_array_equal(q.grid_a.states, p.grid_a.states)
        assert q.grid_b.resolution == 0.1 and q.grid_b.origin == (-1.5, -2.0)
        assert (q.overlap, q.world_id, q.seed, q.explorer, q.step, q.episode, q.snapshot) == (
            p.overlap, p.world_id, p.seed, p.explorer, p.step, p.episode, p.snapshot)
        assert q.extra == {"coverage": 0.5}
        # the stored truth maps B's nodes onto the matching nodes of A
        np.testing.assert_allclose(q.transform.apply(q.map_b.xy), q.map_a.xy[:4], atol=1e-9)
    rows = write_index(root)
    assert json.loads((root / "index.json").read_text())["pairs"] == rows
    assert rows[2]["nodes_b"] == 4


def test_corrupt_and_foreign_files_are_named(tmp_path):
    root = new_dataset(tmp_path)
    path = write_pair(root, make_pair(0, np.random.default_rng(1)))
    path.write_bytes(path.read_bytes()[:100])  # truncated
    with pytest.raises(DatasetError, match=r"pair_000000\.npz: corrupt or not a map-pair file"):
        load_pairs(root)
    path.unlink()
    (root / "pairs" / "notes.txt").write_text("hello")
    with pytest.raises(DatasetError, match=r"notes\.txt: foreign file in a map-pair dataset"):
        load_pairs(root)


def test_foreign_npz_and_missing_manifest(tmp_path):
    with pytest.raises(DatasetError, match=r"dataset\.json: missing"):
        load_pairs(tmp_path)
    root = new_dataset(tmp_path)
    path = pair_path(root, 5)
    path.parent.mkdir(parents=True)
    np.savez(path, meta=np.array(json.dumps({"format": "other", "version": 1})))
    with pytest.raises(DatasetError, match=r"pair_000005\.npz: not a topomerge.map_pairs version 1"):
        read_pair(path)
    (root / "dataset.json").write_text('{"format": "topomerge.map_pairs", "version": 9}')
    with pytest.raises(DatasetError, match="version 9 is not supported"):
        load_pairs(root)


def test_interrupted_write_leaves_only_a_temp_file(tmp_path, monkeypatch):
    root = new_dataset(tmp_path)
    write_pair(root, make_pair(0, np.random.default_rng(2)))

    def crash(src, dst):
        raise KeyboardInterrupt

    monkeypatch.setattr("topo.fileio.os.replace", crash)
    with pytest.raises(KeyboardInterrupt):
        write_pair(root, make_pair(1, np.random.default_rng(3)))
    monkeypatch.undo()
    assert sorted(pair_files(root)) == [0]  # no half-written pair 1
    assert [p.pair_id for p in load_pairs(root)] == [0]


def test_left_over_temp_files_are_ignored_and_cleaned(tmp_path):
    root = new_dataset(tmp_path)
    write_pair(root, make_pair(0, np.random.default_rng(4)))
    stale = root / "pairs" / ".tmp-killed.npz"
    stale.write_bytes(b"half a file")
    assert [p.pair_id for p in load_pairs(root)] == [0]
    pair_files(root, clean_temp=True)
    assert not stale.exists()

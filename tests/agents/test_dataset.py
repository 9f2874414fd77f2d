"""Map-pair dataset generation: round trip with ground truth, resume, workers, Ray, CLI."""

import numpy as np
import pytest
from scipy import ndimage

import agents.dataset as dataset
from agents.dataset import GenerateArgs, coverage_levels, episode_seed, generate, info, main
from fusion import Rigid2D
from fusion.pairs import DatasetError, load_pairs, pair_files
from topo.grid import CellState

KW = {"explorer": "frontier", "snapshots": 2, "max_cycles": 200, "world_size": (10.0, 10.0),
      "progress": False}


def fields(pair):
    return (pair.pair_id, pair.step, pair.seed, pair.world_id, round(pair.overlap, 12),
            pair.map_a.xy.round(9).tolist(), pair.map_b.edges.tolist(),
            pair.grid_b.states.tobytes(), round(pair.transform.theta, 12))


def wall_agreement(pair, transform) -> float:
    """Share of B's occupied cells, moved into A's frame by ``transform``, that land within two
    cells of an occupied cell of A (counting only cells A knows)."""
    a, b = pair.grid_a, pair.grid_b
    h, w = a.states.shape
    rows, cols = np.nonzero(b.states == CellState.OCCUPIED)
    xy = np.stack([b.origin[0] + (cols + 0.5) * b.resolution,
                   b.origin[1] + (rows + 0.5) * b.resolution], 1)
    ia = np.floor((transform.apply(xy) - a.origin) / a.resolution).astype(int)
    ia = ia[(ia[:, 0] >= 0) & (ia[:, 0] < w) & (ia[:, 1] >= 0) & (ia[:, 1] < h)]
    known = a.states[ia[:, 1], ia[:, 0]] != CellState.UNKNOWN
    walls = ndimage.binary_dilation(a.states == CellState.OCCUPIED, iterations=2)
    return float(walls[ia[known, 1], ia[known, 0]].mean()) if known.sum() > 30 else float("nan")


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("ref")
    generate(GenerateArgs(out=out, pairs=4, **KW))
    return out, load_pairs(out)


def test_round_trip_and_ground_truth(reference):
    out, pairs = reference
    assert [p.pair_id for p in pairs] == [0, 1, 2, 3]
    assert {p.episode for p in pairs} == {0, 1} and [p.snapshot for p in pairs] == [0, 1, 0, 1]
    assert pairs[0].seed == episode_seed(0, 0) and pairs[2].seed == episode_seed(0, 1)
    assert all(p.step >= 1 and p.explorer == "frontier" for p in pairs)
    assert pairs[0].step <= pairs[1].step
    # the stored transform takes B's frame onto A's: B's walls land on A's walls, and a
    # transform 10° / 0.3 m off does much worse
    # (of the pairs that overlap, the one with the most walls: small early maps discriminate
    # little)
    best = max((p for p in pairs if p.overlap > 0.3),
               key=lambda p: int((p.grid_b.states == CellState.OCCUPIED).sum()))
    off = Rigid2D.from_degrees(10.0, (0.3, 0.0)) @ best.transform
    assert wall_agreement(best, best.transform) > 0.7
    assert wall_agreement(best, best.transform) > wall_agreement(best, off) + 0.2
    assert "4 pairs" in info(out)


def test_resume_after_an_interruption_gives_the_same_pairs(reference, tmp_path, monkeypatch):
    real = dataset.generate_episode

    def dies_on_episode_1(root, episode, n_pairs, settings):
        if episode == 1:
            raise KeyboardInterrupt
        return real(root, episode, n_pairs, settings)

    monkeypatch.setattr(dataset, "generate_episode", dies_on_episode_1)
    with pytest.raises(KeyboardInterrupt):
        generate(GenerateArgs(out=tmp_path, pairs=4, **KW))
    assert sorted(pair_files(tmp_path)) == [0, 1]
    monkeypatch.setattr(dataset, "generate_episode", real)
    summary = generate(GenerateArgs(out=tmp_path, pairs=4, **KW))
    assert summary["already_there"] == 2 and summary["written"] == 2
    assert [fields(p) for p in load_pairs(tmp_path)] == [fields(p) for p in reference[1]]
    again = generate(GenerateArgs(out=tmp_path, pairs=4, **KW))  # nothing left to do
    assert again["written"] == 0


def test_worker_processes_give_the_same_pairs(reference, tmp_path):
    generate(GenerateArgs(out=tmp_path, pairs=4, workers=2, **KW))
    assert [fields(p) for p in load_pairs(tmp_path)] == [fields(p) for p in reference[1]]


def test_ray_backend_gives_the_same_pairs(reference, tmp_path):
    pytest.importorskip("ray")
    generate(GenerateArgs(out=tmp_path, pairs=4, workers=2, backend="ray", **KW))
    assert [fields(p) for p in load_pairs(tmp_path)] == [fields(p) for p in reference[1]]


def test_changed_settings_refuse_to_resume(reference, tmp_path):
    generate(GenerateArgs(out=tmp_path, pairs=2, **KW))
    with pytest.raises(DatasetError, match="was generated with settings"):
        generate(GenerateArgs(out=tmp_path, pairs=2, **{**KW, "explorer": "random_walk"}))


def test_cli_generate_and_info(tmp_path, capsys):
    main(["generate", "--out", str(tmp_path), "--pairs", "1", "--snapshots", "1",
          "--max-cycles", "30", "--explorer", "random_walk", "--no-progress"])
    assert "wrote 1 pairs" in capsys.readouterr().out
    main(["info", str(tmp_path)])
    assert "1 pairs" in capsys.readouterr().out


def test_snapshot_levels_spread():
    np.testing.assert_allclose(coverage_levels(2), [0.325, 0.675])


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"pairs": 0}, "pairs must be >= 1, got 0"),
        ({"backend": "spark"}, r"backend must be one of \['process', 'ray'\], got 'spark'"),
        ({"address": "auto"}, "address is only used with backend='ray'"),
        ({"explorer": "spiral"}, r"explorer must be one of \["),
        ({"explorer": "sb3:/nowhere/model.zip"}, "no saved model at '/nowhere/model.zip'"),
        ({"world": "/nowhere/map.yaml"}, "world must be 'procedural' or an existing map file"),
    ],
)
def test_bad_arguments(tmp_path, kwargs, match):
    with pytest.raises(ValueError, match=match):
        GenerateArgs(out=tmp_path, **kwargs)

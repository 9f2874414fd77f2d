"""Synthetic map pairs: ground truth that holds, determinism, the no-overlap kinds, validation."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fusion.evaluation.synthetic import (
    GENERIC_CONFIG,
    PAIR_KINDS,
    SyntheticConfig,
    generate_pairs,
    generic_pairs,
    make_pair,
    pair_kind,
    random_world,
)
from topo.graph import NodeKind

NOISELESS = SyntheticConfig(noise=0.0)


@settings(max_examples=12, deadline=None)
@given(seed=st.integers(0, 2**32 - 1), overlap=st.floats(0.2, 1.0))
def test_truth_maps_corresponding_nodes_exactly_without_noise(seed, overlap):
    p = make_pair(np.random.default_rng(seed), NOISELESS, overlap=overlap, nodes=(20, 25))
    assert p.kind == "overlap"  # (drops and boundary effects may leave no shared node)
    a = p.map_a.xy[p.correspondences[:, 0]]
    b = p.transform.apply(p.map_b.xy[p.correspondences[:, 1]])
    np.testing.assert_allclose(a, b, atol=1e-9)


def test_large_overlap_shares_many_nodes():
    p = make_pair(np.random.default_rng(1), overlap=0.9, nodes=(40, 40))
    assert p.n_shared >= 15 and p.overlap > 0.8


def test_noise_moves_nodes_by_about_sigma():
    p = make_pair(np.random.default_rng(5), SyntheticConfig(noise=0.15), overlap=0.9,
                  nodes=(40, 40))
    d = p.map_a.xy[p.correspondences[:, 0]] - p.transform.apply(
        p.map_b.xy[p.correspondences[:, 1]])
    assert 0.1 < d.std() < 0.3  # per-axis difference of two noisy copies: σ√2 ≈ 0.21


def test_same_seed_same_pairs_and_pairs_independent_of_count():
    first = list(generate_pairs(6, seed=3))
    again = list(generate_pairs(6, seed=3))
    for p, q in zip(first, again, strict=True):
        assert p.map_a.equals(q.map_a) and p.map_b.equals(q.map_b)
        assert p.transform.allclose(q.transform, atol=0.0)
        np.testing.assert_array_equal(p.correspondences, q.correspondences)
    longer = list(generate_pairs(10, seed=3))
    assert longer[0].map_a.equals(first[0].map_a)
    assert not list(generate_pairs(6, seed=4))[0].map_a.equals(first[0].map_a)


def test_generated_set_covers_overlaps_kinds_and_rotations():
    pairs = list(generate_pairs(30, seed=1))
    kinds = [p.kind for p in pairs]
    assert kinds.count("disjoint") == 3 and kinds.count("other_world") == 3
    overlaps = sorted(p.overlap for p in pairs if p.kind == "overlap")
    assert overlaps[0] < 0.2 and overlaps[-1] > 0.8
    angles = np.array([p.true_rotation_deg for p in pairs])
    assert angles.min() < -90 and angles.max() > 90


@pytest.mark.parametrize("kind", ["disjoint", "other_world"])
def test_no_overlap_pairs_share_nothing(kind):
    p = make_pair(np.random.default_rng(2), kind=kind, nodes=(30, 30))
    assert p.kind == kind and p.overlap == 0.0 and p.n_shared == 0


def test_maps_look_extracted():
    p = make_pair(np.random.default_rng(8), overlap=0.5, nodes=(40, 40))
    for m in (p.map_a, p.map_b):
        assert m.n_nodes >= 3
        degree = m.degree()
        assert np.all(degree >= 1)  # no isolated places
        assert np.all(m.kinds[degree == 1] == NodeKind.DEAD_END)
        assert np.all(m.kinds[degree >= 3] == NodeKind.JUNCTION)


def test_world_is_connected_with_places_only():
    w = random_world(np.random.default_rng(0), (8, 8))
    assert np.all(np.isfinite(w.dist))
    assert np.all(w.topomap().degree() != 0)


def test_pair_kind_layout():
    assert [pair_kind(i, 10, 0.2) for i in range(10)] == ["overlap"] * 8 + [
        "disjoint", "other_world"]
    assert set(PAIR_KINDS) == {"overlap", "disjoint", "other_world"}


def test_bad_config_and_arguments():
    with pytest.raises(ValueError, match="noise must be >= 0.0, got -1.0"):
        SyntheticConfig(noise=-1.0)
    with pytest.raises(ValueError, match=r"map_nodes must satisfy 3 <= low <= high, got \(5, 2\)"):
        SyntheticConfig(map_nodes=(5, 2))
    with pytest.raises(TypeError, match="spacing must be a \\(low, high\\) pair, got 3.0"):
        SyntheticConfig(spacing=3.0)
    with pytest.raises(ValueError, match=r"SyntheticConfig has unknown keys \['sigma'\]"):
        SyntheticConfig.from_dict({"sigma": 0.1})
    with pytest.raises(ValueError, match="kind must be one of"):
        make_pair(np.random.default_rng(0), kind="partial")
    with pytest.raises(ValueError, match="overlap must be <= 1.0, got 1.5"):
        make_pair(np.random.default_rng(0), overlap=1.5)
    with pytest.raises(ValueError, match="n must be >= 0, got -1"):
        list(generate_pairs(-1))


def test_generic_pairs_follow_their_config_at_every_noise_level():
    quiet, noisy = (list(generic_pairs(10, 3, noise)) for noise in (0.0, 0.1))
    assert [p.kind for p in quiet] == [pair_kind(i, 10, 0.2) for i in range(10)]
    lo, hi = GENERIC_CONFIG.overlap_range
    assert all(lo - 0.1 <= p.overlap <= hi for p in quiet if p.kind == "overlap")
    for a, b in zip(quiet, noisy, strict=True):  # the same worlds, only the noise differs
        assert a.transform.allclose(b.transform, atol=0.0) and a.noise == 0.0 and b.noise == 0.1
    p = quiet[0]
    moved = p.transform.apply(p.map_b.xy[p.correspondences[:, 1]])
    np.testing.assert_allclose(p.map_a.xy[p.correspondences[:, 0]], moved, atol=1e-9)
    with pytest.raises(ValueError, match="noise must be >= 0.0"):
        generic_pairs(3, 0, -0.1)

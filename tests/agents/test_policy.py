"""TopoExplorerExtractor: shapes, padding is ignored, node order does not matter; SectorPolicy."""

import math

import numpy as np
import pytest
import torch
from gymnasium import spaces

from agents.policy import TopoExplorerExtractor

torch.set_num_threads(1)
N = 12


def obs_space() -> spaces.Dict:
    return spaces.Dict({
        "sonar": spaces.Box(0, 1, (8,), np.float32),
        "odometry": spaces.Box(np.array([-30, -30, -1, -1], np.float32),
                               np.array([30, 30, 1, 1], np.float32)),
        "graph_nodes": spaces.Box(-60, 60, (N, 6), np.float32),
        "graph_mask": spaces.Box(0, 1, (N,), np.float32),
        "graph_adjacency": spaces.Box(0, 1, (N, N), np.float32),
        "local_map": spaces.Box(0, 255, (1, 64, 64), np.uint8),
        "teammate": spaces.Box(-60, 60, (5,), np.float32),
    })


def batch(rng: np.random.Generator, n_real: int) -> dict[str, torch.Tensor]:
    sp = obs_space()
    obs = {k: torch.as_tensor(np.stack([s.sample() for _ in range(3)]), dtype=torch.float32)
           for k, s in sp.spaces.items()}
    mask = np.zeros((3, N), np.float32)
    mask[:, :n_real] = 1
    adj = (rng.uniform(size=(3, N, N)) < 0.3).astype(np.float32)
    adj = np.maximum(adj, adj.transpose(0, 2, 1)) * mask[:, :, None] * mask[:, None, :]
    obs["graph_mask"] = torch.as_tensor(mask)
    obs["graph_adjacency"] = torch.as_tensor(adj)
    obs["local_map"] = obs["local_map"] / 255.0
    return obs


def test_output_shape_and_finiteness():
    ex = TopoExplorerExtractor(obs_space())
    out = ex(batch(np.random.default_rng(0), 5))
    assert out.shape == (3, ex.features_dim) and torch.isfinite(out).all()


def test_graph_encoding_is_permutation_invariant_and_ignores_padding():
    torch.manual_seed(0)
    ex = TopoExplorerExtractor(obs_space())
    rng = np.random.default_rng(1)
    obs = batch(rng, 7)
    base = ex(obs)
    perm = torch.as_tensor(rng.permutation(N))
    permuted = dict(obs)
    permuted["graph_nodes"] = obs["graph_nodes"][:, perm]
    permuted["graph_mask"] = obs["graph_mask"][:, perm]
    permuted["graph_adjacency"] = obs["graph_adjacency"][:, perm][:, :, perm]
    torch.testing.assert_close(ex(permuted), base, atol=1e-5, rtol=1e-5)
    padded = dict(obs)  # garbage in padded slots changes nothing
    nodes = obs["graph_nodes"].clone()
    nodes[:, 7:] = 1e3
    padded["graph_nodes"] = nodes
    torch.testing.assert_close(ex(padded), base, atol=1e-5, rtol=1e-5)


def test_needs_the_env_keys():
    with pytest.raises(ValueError, match=r"lacks keys \['graph_mask'\]"):
        TopoExplorerExtractor(spaces.Dict({k: v for k, v in obs_space().spaces.items()
                                           if k != "graph_mask"}))
    with pytest.raises(TypeError, match="needs a Dict observation space, got Box"):
        TopoExplorerExtractor(spaces.Box(0, 1, (3,)))


def goal_space() -> spaces.Dict:
    return spaces.Dict({**obs_space().spaces,
                        "frontiers": spaces.Box(0, 1, (8, 3), np.float32)})


def test_sector_scorer_is_one_network_for_every_sector():
    """Swapping two sectors' rows swaps their logits once the direction input is silenced: the
    same weights score every sector."""
    from agents.policy import SectorScorer

    torch.manual_seed(0)
    scorer = SectorScorer(context_dim=16, sectors=8, row=3, hidden=32)
    with torch.no_grad():
        scorer.net[0].weight[:, -8:] = 0.0  # the direction one-hot
    latent = torch.rand(4, 16 + 8 * 3)
    swapped = latent.clone().view(4, -1)
    rows = swapped[:, 16:].view(4, 8, 3)
    rows[:, [2, 6]] = rows[:, [6, 2]].clone()
    base, other = scorer(latent), scorer(swapped)
    torch.testing.assert_close(other[:, [6, 2]], base[:, [2, 6]])
    torch.testing.assert_close(other[:, [0, 1, 3, 4, 5, 7]], base[:, [0, 1, 3, 4, 5, 7]])


def test_sector_mask_leaves_only_sectors_with_a_frontier():
    from agents.policy import MASKED_LOGIT, SectorScorer

    torch.manual_seed(0)
    scorer = SectorScorer(context_dim=16, sectors=8, row=3, hidden=32, mask_empty=True)
    latent = torch.rand(3, 16 + 8 * 3)
    rows = latent[:, 16:].view(3, 8, 3)
    rows[..., 0] = 0.0
    rows[0, [1, 6], 0] = 1.0  # two sectors with a frontier
    rows[1, 3, 0] = 1.0  # one
    logits = scorer(latent)  # row 2: none, so nothing is masked
    assert torch.isfinite(torch.distributions.Categorical(logits=logits).entropy()).all()
    probs = torch.softmax(logits, dim=1)
    assert (probs[0, [0, 2, 3, 4, 5, 7]] == 0).all() and probs[0, [1, 6]].sum() == 1
    assert probs[1, 3] == 1 and (logits[1, [0, 1, 2, 4, 5, 6, 7]] == MASKED_LOGIT).all()
    assert (logits[2] > MASKED_LOGIT).all()
    unmasked = SectorScorer(context_dim=16, sectors=8, row=3, hidden=32)
    unmasked.load_state_dict(scorer.state_dict())
    assert (unmasked(latent) > MASKED_LOGIT).all()


def test_sector_policy_acts_and_checks_its_spaces():
    from agents.policy import SectorPolicy

    policy = SectorPolicy(goal_space(), spaces.Discrete(8), lambda _: 3e-4)
    obs = {k: torch.as_tensor(np.stack([s.sample() for _ in range(5)]), dtype=torch.float32)
           for k, s in goal_space().spaces.items()}
    probs = policy.get_distribution(obs).distribution.probs
    assert probs.shape == (5, 8) and torch.allclose(probs.sum(1), torch.ones(5))
    with pytest.raises(TypeError, match="needs a Discrete action space"):
        SectorPolicy(goal_space(), spaces.Box(-1, 1, (2,)), lambda _: 3e-4)
    with pytest.raises(ValueError, match=r"'frontiers' observation of shape \(5, F\)"):
        SectorPolicy(goal_space(), spaces.Discrete(5), lambda _: 3e-4)


def test_cost_prior_starts_the_policy_as_a_soft_frontier():
    """With a cost prior and an untrained scorer (its last layer near zero), the likeliest
    sector is the one holding the cheapest frontier, and a sector 1 m dearer is e^prior less
    likely."""
    from agents.goals import COST_SCALE, FRONTIER_FEATURES
    from agents.policy import SectorPolicy

    space = spaces.Dict({**obs_space().spaces,
                         "frontiers": spaces.Box(0, 1, (8, len(FRONTIER_FEATURES)), np.float32)})
    policy = SectorPolicy(space, spaces.Discrete(8), lambda _: 3e-4, cost_prior=2.0)
    obs = {k: torch.as_tensor(np.stack([s.sample() for _ in range(4)]), dtype=torch.float32)
           for k, s in space.spaces.items()}
    gap = FRONTIER_FEATURES.index("cost_gap")
    obs["frontiers"][:, :, 0] = 1.0
    obs["frontiers"][:, :, gap] = 5.0 / COST_SCALE
    obs["frontiers"][:, 3, gap] = 0.0  # the cheapest frontier lies in sector 3
    obs["frontiers"][:, 6, gap] = 1.0 / COST_SCALE  # 1 m dearer
    logits = policy.get_distribution(obs).distribution.logits
    assert (logits.argmax(1) == 3).all()
    ratio = torch.exp(logits[:, 3] - logits[:, 6])
    torch.testing.assert_close(ratio, torch.full((4,), math.e ** 2), rtol=0.1, atol=0)
    with pytest.raises(ValueError, match="cost_prior must be >= 0"):
        SectorPolicy(space, spaces.Discrete(8), lambda _: 3e-4, cost_prior=-1.0)
    from agents.policy import SectorScorer

    with pytest.raises(ValueError, match="model_config cost_prior must be >= 0"):
        SectorScorer(16, 8, len(FRONTIER_FEATURES), 32, cost_prior=-1.0,
                     name="model_config cost_prior")
    with pytest.raises(ValueError, match=r"cost_prior needs the 6 frontiers columns of "
                                         r"agents.goals.FRONTIER_FEATURES, got 3"):
        SectorScorer(16, 8, 3, 32, cost_prior=1.0)


def test_central_critic_reads_the_global_state_and_the_actor_does_not():
    """With a ``state`` observation the value changes with it and the action distribution does
    not (decentralised actors): zeros at inference are then as good as the true state."""
    from agents.policy import SectorPolicy

    space = spaces.Dict({**goal_space().spaces, "state": spaces.Box(0, 1, (40,), np.float32)})
    torch.manual_seed(0)
    policy = SectorPolicy(space, spaces.Discrete(8), lambda _: 3e-4, state_features=16)
    obs = {k: torch.zeros((4, *s.shape)) for k, s in space.spaces.items()}
    obs["frontiers"][:, :, 0] = 1.0
    obs["state"] = torch.rand(4, 40, generator=torch.Generator().manual_seed(1))
    zeroed = {**obs, "state": torch.zeros(4, 40)}
    torch.testing.assert_close(policy.get_distribution(obs).distribution.logits,
                               policy.get_distribution(zeroed).distribution.logits)
    assert not torch.allclose(policy.predict_values(obs), policy.predict_values(zeroed))
    assert policy.mlp_extractor.n_state == 16
    plain = SectorPolicy(goal_space(), spaces.Discrete(8), lambda _: 3e-4)
    assert plain.mlp_extractor.n_state == 0 and plain.features_extractor.state_features == 0


def team_space(n_robots: int) -> spaces.Dict:
    """``obs_space`` as ``multi_robot_explore_v0`` lays it out: ``teammates`` (N - 1, 7)."""
    sp = {k: v for k, v in obs_space().spaces.items() if k != "teammate"}
    lo = np.array([-60, -60, -1, -1, 0, 0, 0], np.float32)
    hi = np.array([60, 60, 1, 1, 1, 1, 1], np.float32)
    return spaces.Dict({**sp, "teammates": spaces.Box(np.tile(lo, (n_robots - 1, 1)),
                                                      np.tile(hi, (n_robots - 1, 1)))})


def team_batch(n_robots: int, seed: int) -> dict[str, torch.Tensor]:
    sp = team_space(n_robots)
    sp.seed(seed)
    return {k: torch.as_tensor(np.stack([s.sample() for _ in range(3)]), dtype=torch.float32)
            for k, s in sp.spaces.items()}


def test_two_robot_layout_keeps_its_parameters():
    """A ``teammate`` observation builds exactly the modules it always did (saved policies
    load): no teammate-set encoder, and the vector MLP reads the 17 values as before."""
    torch.manual_seed(0)
    ex = TopoExplorerExtractor(obs_space())
    assert not ex.team and ex.vector_keys == ("sonar", "odometry", "teammate")
    assert not any(k.startswith("team") for k in ex.state_dict())
    assert ex.vector[0].in_features == 8 + 4 + 5


@pytest.mark.parametrize("n_robots", [3, 4])
def test_teammates_rows_are_encoded_as_a_set(n_robots):
    """With ``teammates`` the features have the two-robot width, do not depend on the
    teammates' order, and the weights are the same shapes for every team size."""
    torch.manual_seed(0)
    ex = TopoExplorerExtractor(team_space(n_robots))
    assert ex.features_dim == TopoExplorerExtractor(obs_space()).features_dim
    obs = team_batch(n_robots, 1)
    base = ex(obs)
    assert base.shape == (3, ex.features_dim) and torch.isfinite(base).all()
    reordered = {**obs, "teammates": obs["teammates"].flip(1)}
    torch.testing.assert_close(ex(reordered), base, atol=1e-5, rtol=1e-5)
    moved = obs["teammates"].clone()
    moved[:, 0, :2] += 20.0
    assert not torch.allclose(ex({**obs, "teammates": moved}), base)
    other = TopoExplorerExtractor(team_space(2 if n_robots == 4 else 5))
    other.load_state_dict(ex.state_dict())  # one set of weights serves any team size


def test_teammates_needs_rows_of_features():
    sp = {**team_space(3).spaces, "teammates": spaces.Box(0, 1, (14,), np.float32)}
    with pytest.raises(ValueError, match=r"'teammates' must be \(teammates, features\), "
                                         r"got shape \(14,\)"):
        TopoExplorerExtractor(spaces.Dict(sp))
    sp = {k: v for k, v in team_space(3).spaces.items() if k != "teammates"}
    with pytest.raises(ValueError, match=r"lacks keys \['teammate'\]"):
        TopoExplorerExtractor(spaces.Dict(sp))

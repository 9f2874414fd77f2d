"""Stable-Baselines3 adapter: PettingZoo ``ParallelEnv`` → SB3 ``VecEnv`` with parameter sharing.

Every agent of every env is one sub-environment of the ``VecEnv``: with ``n`` envs of ``N`` robots
(two for ``two_robot_explore_v0``, 2–8 for ``multi_robot_explore_v0``), ``num_envs = N n`` and one
policy drives all robots (parameter sharing).

Why not SuperSuit (``pettingzoo_env_to_vec_env_v1`` + ``concat_vec_envs_v1``): with SB3 2.9 its
wrapper has no ``seed()``, so ``PPO(seed=...)`` fails, and making its episode-end bookkeeping
match SB3's is more work than this adapter. The semantics here are exactly those of SB3's
``DummyVecEnv.step_wait``:

* when an env's episode ends (all its agents terminated or truncated — the robots always end
  together), each of its sub-environments reports ``done=True``, its info gets
  ``"terminal_observation"`` (the last observation) and ``"TimeLimit.truncated"`` (truncated and
  not terminated), and the returned observation is already the first of the next episode
  (auto-reset);
* ``VecEnv.seed(s)`` seeds env ``j`` with ``s + j · n_agents`` on the next ``reset()`` (SB3
  gives sub-environment ``i`` the seed ``s + i``; the first agent's slot seeds its env); later
  auto-resets continue the env's own generator, so a run is reproducible from ``s``.

Multi-process (``n_workers > 1``): the envs are split across worker processes, each stepping its
share in one call per step (like ``SubprocVecEnv``, but a worker holds several envs). Infos
cross the process boundary *light*: only numbers, strings and small arrays (≤ 64 values) are
kept. ``two_robot_explore``'s own infos are all of that kind; the filter
guards against wrappers that add objects, which would be pickled every step. Use
``n_workers=1`` to see every info.
"""

from __future__ import annotations

import multiprocessing as mp
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from stable_baselines3.common.vec_env import VecEnv
from stable_baselines3.common.vec_env.base_vec_env import CloudpickleWrapper

from topo.validation import check_int

EnvFactory = Callable[[], Any]


class EnvGroup:
    """Several ``ParallelEnv`` stepped together, flattened to one slot per (env, agent).

    The one stepping mechanism of :class:`ParallelVecEnv`, used in-process or inside a worker.
    """

    def __init__(self, env_fns: Sequence[EnvFactory], light_infos: bool = False) -> None:
        self.envs = [fn() for fn in env_fns]
        self.light_infos = light_infos
        self.agents = list(self.envs[0].possible_agents)
        for k, env in enumerate(self.envs):
            if list(env.possible_agents) != self.agents:
                raise ValueError(f"env_fns[{k}] has agents {env.possible_agents}, expected "
                                 f"{self.agents} like env_fns[0]")

    def spaces(self) -> tuple[gym.Space, gym.Space, int]:
        env, agent = self.envs[0], self.agents[0]
        for a in self.agents[1:]:
            if env.observation_space(a) != env.observation_space(agent) or (
                    env.action_space(a) != env.action_space(agent)):
                raise ValueError("parameter sharing needs every agent to have the same "
                                 f"spaces; {a!r} differs from {agent!r}")
        return env.observation_space(agent), env.action_space(agent), len(self.agents)

    def reset(self, seeds: Sequence[int | None], options: Sequence[dict]) -> tuple[list, list]:
        obs, infos = [], []
        for env, seed, opt in zip(self.envs, seeds, options, strict=True):
            o, i = env.reset(seed=seed, options=opt or None)
            obs += [o[a] for a in self.agents]
            infos += [self._info(i.get(a, {})) for a in self.agents]
        return obs, infos

    def step(self, actions: Sequence[Any]) -> tuple[list, np.ndarray, np.ndarray, list]:
        n = len(self.agents)
        obs, rewards, dones, infos = [], [], [], []
        for j, env in enumerate(self.envs):
            acts = {a: actions[j * n + k] for k, a in enumerate(self.agents)}
            o, r, term, trunc, info = env.step(acts)
            ended = [bool(term[a] or trunc[a]) for a in self.agents]
            if any(ended) and not all(ended):
                raise RuntimeError("ParallelVecEnv needs all agents of an env to end together; "
                                   f"got terminations {term} and truncations {trunc}")
            slot_infos = [self._info(info.get(a, {})) for a in self.agents]
            slot_obs = [o[a] for a in self.agents]
            if all(ended):
                for k, a in enumerate(self.agents):
                    slot_infos[k]["terminal_observation"] = slot_obs[k]
                    slot_infos[k]["TimeLimit.truncated"] = bool(trunc[a] and not term[a])
                reset_obs, _ = env.reset()
                slot_obs = [reset_obs[a] for a in self.agents]
            obs += slot_obs
            rewards += [float(r[a]) for a in self.agents]
            dones += ended
            infos += slot_infos
        return obs, np.asarray(rewards, dtype=np.float32), np.asarray(dones), infos

    def _info(self, info: dict) -> dict:
        if not self.light_infos:
            return dict(info)
        return {k: v for k, v in info.items() if _is_light(v)}

    def call(self, slot: int, method: str, args: tuple, kwargs: dict) -> Any:
        return getattr(self.envs[slot // len(self.agents)], method)(*args, **kwargs)

    def get_attr(self, slot: int, name: str) -> Any:
        return getattr(self.envs[slot // len(self.agents)], name)

    def set_attr(self, slot: int, name: str, value: Any) -> None:
        setattr(self.envs[slot // len(self.agents)], name, value)

    def render(self) -> list[Any]:
        return [env.render() for env in self.envs]

    def close(self) -> None:
        for env in self.envs:
            env.close()


def _is_light(value: Any) -> bool:
    """Cheap to send to another process: a number, string or an array of at most 64 values."""
    if isinstance(value, (bool, int, float, str, np.number)) or value is None:
        return True
    return isinstance(value, np.ndarray) and value.size <= 64


def _worker(remote: Any, parent: Any, fns: CloudpickleWrapper) -> None:
    parent.close()
    group = EnvGroup(fns.var, light_infos=True)
    try:
        while True:
            cmd, args = remote.recv()
            if cmd == "close":
                group.close()
                remote.send(None)
                break
            remote.send(getattr(group, cmd)(*args))
    except KeyboardInterrupt:
        pass


class ParallelVecEnv(VecEnv):
    """An SB3 ``VecEnv`` over PettingZoo ``ParallelEnv`` factories (see the module docstring).

    Args:
        env_fns: callables each building one ``ParallelEnv``; all with the same agents and
            spaces.
        n_workers: ``1`` steps every env in this process; ``k > 1`` splits them over ``k``
            worker processes (at most one per env).
        start_method: multiprocessing start method for workers (default ``"forkserver"`` where
            available, else ``"spawn"``).
    """

    def __init__(self, env_fns: Sequence[EnvFactory], n_workers: int = 1,
                 start_method: str | None = None) -> None:
        if not env_fns or not all(callable(f) for f in env_fns):
            raise TypeError("env_fns must be a non-empty sequence of callables returning "
                            "PettingZoo ParallelEnvs")
        n_workers = check_int(n_workers, "n_workers", low=1)
        self.n_envs = len(env_fns)
        self._remotes: list[Any] = []
        self._processes: list[Any] = []
        self._local: EnvGroup | None = None
        if n_workers == 1:
            self._local = EnvGroup(env_fns)
            obs_space, act_space, n_agents = self._local.spaces()
            self._slices = [range(self.n_envs)]
        else:
            n_workers = min(n_workers, self.n_envs)
            self._slices = [r.tolist() for r in np.array_split(np.arange(self.n_envs), n_workers)]
            method = start_method or ("forkserver" if "forkserver" in mp.get_all_start_methods()
                                      else "spawn")
            ctx = mp.get_context(method)
            for part in self._slices:
                remote, work = ctx.Pipe()
                proc = ctx.Process(target=_worker, daemon=True, args=(
                    work, remote, CloudpickleWrapper([env_fns[j] for j in part])))
                proc.start()
                work.close()
                self._remotes.append(remote)
                self._processes.append(proc)
            obs_space, act_space, n_agents = self._call_all("spaces")[0]
        self.n_agents = n_agents
        self._actions: np.ndarray | None = None
        self.closed = False
        super().__init__(self.n_envs * n_agents, obs_space, act_space)

    # ------------------------------------------------------------------ transport
    def _call_all(self, cmd: str, per_group_args: Sequence[tuple] | None = None) -> list[Any]:
        args = per_group_args or [()] * len(self._slices)
        if self._local is not None:
            return [getattr(self._local, cmd)(*args[0])]
        for remote, a in zip(self._remotes, args, strict=True):
            remote.send((cmd, a))
        return [remote.recv() for remote in self._remotes]

    def _group_of(self, slot: int) -> tuple[int, int]:
        env = slot // self.n_agents
        for g, part in enumerate(self._slices):
            if env in part:
                return g, (env - part[0]) * self.n_agents + slot % self.n_agents
        raise IndexError(f"sub-environment index {slot} out of range [0, {self.num_envs})")

    def _call_one(self, slot: int, cmd: str, *args: Any) -> Any:
        g, local_slot = self._group_of(slot)
        if self._local is not None:
            return getattr(self._local, cmd)(local_slot, *args)
        self._remotes[g].send((cmd, (local_slot, *args)))
        return self._remotes[g].recv()

    def _stack(self, obs: list[Any]) -> Any:
        if isinstance(self.observation_space, gym.spaces.Dict):
            return {k: np.stack([o[k] for o in obs]) for k in self.observation_space.spaces}
        return np.stack(obs)

    # ------------------------------------------------------------------ VecEnv API
    def reset(self) -> Any:
        seeds = [self._seeds[j * self.n_agents] for j in range(self.n_envs)]
        options = [self._options[j * self.n_agents] for j in range(self.n_envs)]
        args = [([seeds[j] for j in part], [options[j] for j in part]) for part in self._slices]
        obs, infos = [], []
        for o, i in self._call_all("reset", args):
            obs += o
            infos += i
        self.reset_infos = infos
        self._reset_seeds()
        self._reset_options()
        return self._stack(obs)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions)

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict]]:
        if self._actions is None:
            raise RuntimeError("step_wait() called without step_async()")
        args = []
        for part in self._slices:
            lo, hi = part[0] * self.n_agents, (part[-1] + 1) * self.n_agents
            args.append((list(self._actions[lo:hi]),))
        obs, rewards, dones, infos = [], [], [], []
        for o, r, d, i in self._call_all("step", args):
            obs += o
            rewards.append(r)
            dones.append(d)
            infos += i
        self._actions = None
        return self._stack(obs), np.concatenate(rewards), np.concatenate(dones), infos

    def close(self) -> None:
        if self.closed:
            return
        self._call_all("close")
        for proc in self._processes:
            proc.join(timeout=10)
        self.closed = True

    def get_images(self) -> list[np.ndarray | None]:
        images: list[Any] = []
        for group_images in self._call_all("render"):
            images += group_images
        return images

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        if isinstance(indices, int):
            return [indices]
        return list(indices)

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [self._call_one(i, "get_attr", attr_name) for i in self._indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        for i in self._indices(indices):
            self._call_one(i, "set_attr", attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        return [self._call_one(i, "call", method_name, method_args, method_kwargs)
                for i in self._indices(indices)]

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False for _ in self._indices(indices)]

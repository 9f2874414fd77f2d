"""Training throughput of ``train.py``: agent-steps/s (robot env-steps, both robots counted) at
the defaults, per backend, policy level and number of parallel samplers (SB3 worker processes,
RLlib env runners), measured in one process run each.

Usage::

    python benchmarks/train_speed.py                                # ~4 min: SB3, 20k steps a row
    python benchmarks/train_speed.py --backends rllib --levels goals --runners 1,2 --repeats 3 \
        --cpu-split 5
    python benchmarks/train_speed.py --steps 50000

Each row is a real ``train.main`` run (PPO updates included, evaluation and checkpoints off) on
the default 10 m worlds; the rate is the run's ``time/agent_steps_per_s`` at its end. The first
seconds include starting workers and loading the package's numba kernels in each process, so short
runs understate the steady rate a little. RLlib rows also give the mean seconds per training
iteration spent sampling (the env runners, in parallel) and updating (the learner, in this
process, while the runners wait): their split bounds what more runners can gain. Every row
prints the 1-minute load average before and after it, since the machine may be shared; the
next table gives, per backend and level, each sampler count's rate over the first one's
(repeats paired in order). ``--cpu-split N`` adds, for RLlib, the CPU seconds per iteration of
the driver (the learner) and of the busiest env runner, which do not depend on the machine's
other load: their sum bounds the iteration's length with a free core per process, so the ratio
of those sums bounds the speed-up of more runners.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import os
import platform
import tempfile
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

import train


def scalars(run_dir: Path) -> dict[str, list[float]]:
    """Every scalar series of a run's TensorBoard log (one events file)."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (events,) = {p.parent for p in (run_dir / "tb").rglob("events.out.tfevents.*")}
    acc = EventAccumulator(str(events))
    acc.Reload()
    return {tag: [s.value for s in acc.Scalars(tag)] for tag in acc.Tags()["scalars"]}


def run_row(backend: str, level: str, samplers: int, steps: int, tmp: str, name: str,
            n_envs: int) -> dict[str, float]:
    """One ``train.main`` run; its final rate and (RLlib) mean sample / learn seconds per
    iteration, without the first iteration (start-up, compilation)."""
    extra = ({"num_env_runners": samplers} if backend == "rllib" else {"n_workers": samplers})
    with contextlib.redirect_stdout(io.StringIO()):  # its evaluation table
        run = train.main(train.Args(
            backend=backend, total_timesteps=steps, level=level, n_envs=n_envs, eval_every=0,
            eval_episodes=1, eval_baselines=(), checkpoint_every=0, progress=False,
            runs_dir=Path(tmp), run_name=name, **extra))
    tb = scalars(run)
    out = {"rate": tb["time/agent_steps_per_s"][-1]}
    for key in ("sample_s", "learn_s"):
        series = tb.get(f"time/{key}", [])
        if len(series) > 1:
            out[key] = float(np.mean(series[1:]))
    return out


def cpu_split(level: str, runners: int, iterations: int, n_envs: int) -> dict[str, float]:
    """RLlib at ``train.py``'s defaults with ``runners`` env runners: per training iteration
    (after a first, warm-up one), the wall seconds, the CPU seconds of the driver (the learner
    and RLlib's bookkeeping; it waits while the runners sample) and of the busiest runner.
    CPU seconds do not depend on what else the machine runs, so ``(driver + busiest runner)``
    is the iteration's length with a free core per process."""
    import ray

    from agents.rllib_training import rllib_config, start_ray

    args = train.Args(backend="rllib", level=level, n_envs=n_envs, num_env_runners=runners,
                      progress=False)
    started = start_ray(args)
    algo = rllib_config(args).build_algo()
    group = algo.env_runner_group

    def runner_cpu() -> list[float]:
        return group.foreach_env_runner(lambda _: time.process_time(), local_env_runner=False)

    try:
        algo.train()
        walls, drivers, busiest = [], [], []
        for _ in range(iterations):
            before, wall, cpu = runner_cpu(), time.perf_counter(), time.process_time()
            algo.train()
            walls.append(time.perf_counter() - wall)
            drivers.append(time.process_time() - cpu)
            busiest.append(max(b - a for a, b in zip(before, runner_cpu(), strict=True)))
    finally:
        algo.stop()
        if started:
            ray.shutdown()
    return {"wall": float(np.mean(walls)), "driver": float(np.mean(drivers)),
            "runner": float(np.mean(busiest))}


def print_cpu_split(levels: list[str], counts: list[int], iterations: int, n_envs: int) -> None:
    """The table of :func:`cpu_split` per level and runner count, with each count's bound on
    the speed-up over the first count (from CPU seconds) beside the measured one (wall)."""
    print(f"\n## RLlib: where an iteration's time goes ({iterations} iterations after a "
          "warm-up, means)\n")
    print("| level | env runners | wall s | driver CPU s | busiest runner CPU s | "
          "bound: driver + runner s | speed-up, wall | speed-up bound, free cores | load |\n"
          "|---|---|---|---|---|---|---|---|---|")
    for level in levels:
        first = None
        for n in counts:
            load = os.getloadavg()[0]
            row = cpu_split(level, n, iterations, n_envs)
            bound = row["driver"] + row["runner"]
            first = first or (row["wall"], bound)
            print(f"| {level} | {n} | {row['wall']:.2f} | {row['driver']:.2f} | "
                  f"{row['runner']:.2f} | {bound:.2f} | {first[0] / row['wall']:.2f} | "
                  f"{first[1] / bound:.2f} | {load:.1f} → {os.getloadavg()[0]:.1f} |",
                  flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="agent-steps per row")
    parser.add_argument("--backends", default="sb3", help="sb3, rllib or both (comma-separated)")
    parser.add_argument("--levels", default="goals,motion")
    parser.add_argument("--workers", default="1,2", help="SB3 worker processes per row")
    parser.add_argument("--runners", default="1,2", help="RLlib env runners per row")
    parser.add_argument("--repeats", type=int, default=1, help="runs of each row, interleaved")
    parser.add_argument("--n-envs", type=int, default=4, help="envs (train.py's default: 4)")
    parser.add_argument("--cpu-split", type=int, default=0, metavar="ITERATIONS",
                        help="RLlib: also time this many iterations per runner count by CPU "
                             "seconds of the driver and the runners (0: skip)")
    opts = parser.parse_args()
    print(f"# train.py throughput ({platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}, {os.cpu_count()} cores), "
          f"{opts.steps:,} agent-steps per row, {opts.n_envs} envs\n")
    print("| backend | level | samplers | repeat | agent-steps/s | sample s/iter | learn s/iter "
          "| load before → after |\n|---|---|---|---|---|---|---|---|")
    rates: dict[tuple[str, str], dict[int, list[float]]] = defaultdict(lambda: defaultdict(list))
    with tempfile.TemporaryDirectory() as tmp:
        for repeat in range(opts.repeats):
            for backend in opts.backends.split(","):
                counts = opts.runners if backend == "rllib" else opts.workers
                for level in opts.levels.split(","):
                    for n in (int(c) for c in counts.split(",")):
                        load = os.getloadavg()[0]
                        row = run_row(backend, level, n, opts.steps, tmp,
                                      f"{backend}_{level}_{n}_{repeat}", opts.n_envs)
                        rates[backend, level][n].append(row["rate"])
                        split = " | ".join(f"{row[k]:.2f}" if k in row else "–"
                                           for k in ("sample_s", "learn_s"))
                        print(f"| {backend} | {level} | {n} | {repeat + 1} | {row['rate']:,.0f} | "
                              f"{split} | {load:.1f} → {os.getloadavg()[0]:.1f} |", flush=True)
    print("\n| backend | level | samplers | rate / first count's (per repeat) | mean |\n"
          "|---|---|---|---|---|")
    for (backend, level), by_count in rates.items():
        first = next(iter(by_count.values()))
        for n, values in list(by_count.items())[1:]:
            ratios = [v / f for v, f in zip(values, first, strict=True)]
            print(f"| {backend} | {level} | {n} | {', '.join(f'{r:.2f}' for r in ratios)} | "
                  f"{np.mean(ratios):.2f} |")
    if opts.cpu_split:
        print_cpu_split(opts.levels.split(","), [int(c) for c in opts.runners.split(",")],
                        opts.cpu_split, opts.n_envs)


if __name__ == "__main__":
    main()

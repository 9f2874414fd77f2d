"""Training throughput of ``train.py``: agent-steps/s (robot env-steps, both robots counted) at
the defaults, per policy level and worker count, measured in one process run each.

Usage::

    python benchmarks/train_speed.py                  # ~4 min: 20k agent-steps per row
    python benchmarks/train_speed.py --steps 50000

Each row is a real ``train.main`` run (PPO updates included, evaluation and checkpoints off) on
the default 10 m worlds; the rate is the run's ``time/agent_steps_per_s`` at its end. The first
seconds include starting workers and compiling skan's numba kernels in each process, so short
runs understate the steady rate a little.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import platform
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import train  # noqa: E402


def rate(run_dir: Path) -> float:
    """The last ``time/agent_steps_per_s`` of a run's TensorBoard log."""
    from tensorboard.backend.event_processing.event_accumulator import EventAccumulator

    (events,) = [p.parent for p in (run_dir / "tb").rglob("events.out.tfevents.*")]
    acc = EventAccumulator(str(events))
    acc.Reload()
    return float(acc.Scalars("time/agent_steps_per_s")[-1].value)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="agent-steps per row")
    parser.add_argument("--levels", default="goals,motion")
    parser.add_argument("--workers", default="1,2")
    args = parser.parse_args()
    print(f"# train.py throughput ({platform.processor() or platform.machine()}, "
          f"Python {platform.python_version()}), {args.steps:,} agent-steps per row\n")
    print("| level | n_workers | agent-steps/s |\n|---|---|---|")
    with tempfile.TemporaryDirectory() as tmp:
        for level in args.levels.split(","):
            for workers in (int(w) for w in args.workers.split(",")):
                with contextlib.redirect_stdout(io.StringIO()):  # its evaluation table
                    run = train.main(train.Args(
                        total_timesteps=args.steps, level=level, n_workers=workers,
                        eval_every=0, eval_episodes=1, eval_baselines=(), checkpoint_every=0,
                        progress=False, runs_dir=Path(tmp), run_name=f"{level}_{workers}"))
                print(f"| {level} | {workers} | {rate(run):,.0f} |", flush=True)


if __name__ == "__main__":
    main()

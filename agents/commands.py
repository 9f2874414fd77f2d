"""The ``topomerge`` command: one entry point for what users run.

``topomerge COMMAND [ARGS ...]`` hands ``ARGS`` to the command-line tool it names, imported
only when called (so ``topomerge --help`` stays fast and an optional extra is needed only by
the command that uses it):

| command | runs | same as |
|---|---|---|
| ``demo`` | the ``make demo`` jobs, logs to files, a short summary | ``make demo`` |
| ``dataset generate\\|info`` | map-pair datasets | ``python -m agents.dataset`` |
| ``evaluate`` | the fusion evaluation harness | ``python -m fusion.evaluation`` |
| ``calibrate`` | refit the merges' confidences | ``python -m fusion.calibration`` |
| ``merge`` | merge robots' saved ROS maps | ``python -m fusion merge`` |
| ``train`` | PPO training (SB3 or RLlib) | ``python train.py`` |
| ``bench`` | a benchmark script by name | ``python benchmarks/NAME.py`` |

Every command takes ``--help``. ``demo`` and ``bench`` run files of the source tree
(``examples/``, ``benchmarks/``), so they need the repository (an editable install,
``pip install -e .``); elsewhere they exit with an error naming the missing folder. Why: one
installed name to remember, while the ``python -m`` forms keep working.
"""

from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
"""The source tree this module was loaded from (``examples/`` and ``benchmarks/`` live here)."""

DEMO_STEPS = 30000
"""Agent-steps of the demo's PPO run (``make demo``'s ``DEMO_STEPS``)."""


def _dataset(argv: list[str]) -> int:
    from agents.dataset import main

    main(argv)
    return 0


def _evaluate(argv: list[str]) -> int:
    from fusion.evaluation.evaluate import main

    return main(argv)


def _calibrate(argv: list[str]) -> int:
    from fusion.calibration.__main__ import main

    return main(argv)


def _merge(argv: list[str]) -> int:
    from fusion.mapmerge import main

    return main(argv, prog="topomerge merge")


def _train(argv: list[str]) -> int:
    from train import cli

    cli(argv)
    return 0


def _source_folder(name: str, command: str) -> Path:
    folder = ROOT / name
    if not folder.is_dir():
        raise SystemExit(f"topomerge {command}: error: needs the source tree's {name}/ folder "
                         f"(an editable install: pip install -e .); {folder} does not exist")
    return folder


def bench_scripts() -> dict[str, Path]:
    """Benchmark name → script path (``benchmarks/*.py`` without a leading underscore)."""
    folder = _source_folder("benchmarks", "bench")
    return {p.stem: p for p in sorted(folder.glob("[a-z]*.py"))}


def _bench(argv: list[str]) -> int:
    scripts = bench_scripts()
    if not argv or argv[0] in ("-h", "--help"):
        print("usage: topomerge bench NAME [ARGS ...]\n\nRuns benchmarks/NAME.py with ARGS "
              "(NAME --help for its options; benchmarks/README.md says what each answers).\n\n"
              "benchmarks:\n" + "\n".join(f"  {name}" for name in scripts))
        return 0
    name, rest = argv[0].removesuffix(".py"), argv[1:]
    if name not in scripts:
        print(f"topomerge bench: error: unknown benchmark {argv[0]!r}; choose from "
              f"{', '.join(scripts)}", file=sys.stderr)
        return 2
    return subprocess.run([sys.executable, str(scripts[name]), *rest],
                          env=_child_env(), check=False).returncode


def _child_env() -> dict[str, str]:
    path = os.environ.get("PYTHONPATH", "")
    return {**os.environ, "PYTHONPATH": os.pathsep.join(p for p in (str(ROOT), path) if p),
            "SDL_VIDEODRIVER": os.environ.get("SDL_VIDEODRIVER", "dummy")}


# --- the demo ---------------------------------------------------------------------------------

@dataclass(frozen=True)
class DemoStage:
    """One job of the demo: its command, its log file and the summary lines it prints."""

    name: str
    title: str
    argv: Callable[[Path, int], list[str]]
    summary: Callable[[Path, str], list[str]]


def _rows(pattern: str, text: str) -> list[re.Match]:
    return list(re.finditer(pattern, text, flags=re.MULTILINE))


def _paper_summary(out: Path, log: str) -> list[str]:
    lines = [f"{m[1].strip():<26} {' '.join(m[2].split())}"
             for m in _rows(r"^(\S.{27}|  \+ .{24})R=.*?(rot err.*?ω=\d+)", log)]
    search = re.search(r"^exhaustive search: (\d+ fusions).*?(best ω = .*? optima at [^—]*)",
                       log, flags=re.MULTILINE)
    if search:
        lines.append(f"exhaustive search: {search[1]}; {search[2].strip()}")
    return lines + [f"figures: {out / 'paper_fig8_merged.png'}, "
                    f"{out / 'paper_fig9_convergence.png'}"]


def _episode_summary(out: Path, log: str) -> list[str]:
    keep = (r"^(\S.*(?:seed|steps).*|"
            r"  (?:true coverage|shared map|merges|merge accuracy|pair \(.*).*)$")
    lines = [m[0].rstrip() for m in _rows(keep, log)]
    return lines + [f"figures: {out / 'demo.png'}, {out / 'demo.gif'}, {out / 'team.png'}"]


def _train_summary(out: Path, log: str) -> list[str]:
    run = out / "runs" / "demo"
    table = run / "eval.md"
    lines = []
    if table.is_file():
        rows = [r for r in table.read_text(encoding="utf-8").splitlines() if r.startswith("|")]
        lines = rows[:8]
    return lines + [f"figures: {run / 'eval_coverage.png'}; table {table}; model "
                    f"{run / 'model.zip'}"]


def _last_lines(log: str, n: int) -> list[str]:
    """The last ``n`` non-empty lines, progress bars (carriage returns) reduced to their end."""
    lines = [r.split("\r")[-1].strip() for r in log.splitlines()]
    return [r for r in lines if r and "it/s]" not in r and "pair]" not in r][-n:]


def _dataset_summary(out: Path, log: str) -> list[str]:
    folder = out / "pairs_demo"
    pairs = sorted((folder / "pairs").glob("pair_*.npz"))
    return [f"{len(pairs)} map pairs in {folder}/", *_last_lines(log, 1)]


def _fusion_summary(out: Path, log: str) -> list[str]:
    folder = out / "fusion_demo"
    lines = log.splitlines()
    start = next((i for i, r in enumerate(lines) if r.startswith("method ")), None)
    table = [] if start is None else lines[start:start + 5]
    found = _rows(r"^== (\w+): success against wrong accepts[\s\S]*?^\s*([\d.]+)\*\s+([\d.]+)"
                  r"\s+([\d.]+)", log)
    table += [f"{m[1]} at the env's accept_threshold {m[2]}: {m[3]} % right (overlap >= 40 %), "
              f"{m[4]} % wrong accepts" for m in found]
    return table + [f"full tables: {out / 'logs' / 'fusion.log'}; figures and results.json: "
                    f"{folder}/"]


def _bending_summary(out: Path, log: str) -> list[str]:
    lines = [m[0].rstrip() for m in _rows(r"^(maps that bend, .*|  (?:robot 0's map as "
                                          r"scanned|its working map|its fused map) .*)$", log)]
    return lines + [f"figure: {out / 'bending.png'}"]


def demo_stages() -> tuple[DemoStage, ...]:
    """The demo's jobs in order (the same as ``make demo``'s)."""
    examples = _source_folder("examples", "demo")
    py = sys.executable
    return (
        DemoStage("paper", "1. The paper's example: ICP-SVD and the exhaustive search",
                  lambda out, steps: [py, str(examples / "paper_example.py"), "--out", str(out)],
                  _paper_summary),
        DemoStage("episode", "2. Scripted episodes (two robots; a team of four, 8 m range)",
                  lambda out, steps: [py, str(examples / "demo.py"), "--out", str(out)],
                  _episode_summary),
        DemoStage("train", "3. PPO with fusion in the loop, against scripted explorers",
                  lambda out, steps: [
                      py, "-m", "train", "--total-timesteps", str(steps), "--runs-dir",
                      str(out / "runs"), "--run-name", "demo", "--eval-every", "0",
                      "--eval-episodes", "3", "--checkpoint-every", "0",
                      "--world-size-max", "10", "--overwrite"],
                  _train_summary),
        DemoStage("dataset", "4. Map pairs generated by the trained policy",
                  lambda out, steps: [
                      py, "-m", "agents.dataset", "generate", "--explorer",
                      f"sb3:{out / 'runs' / 'demo' / 'model.zip'}", "--pairs", "9",
                      "--snapshots", "3", "--max-cycles", "800", "--world-size", "16", "16",
                      "--out", str(out / "pairs_demo")],
                  _dataset_summary),
        DemoStage("fusion", "5. Fusion evaluation on those pairs",
                  lambda out, steps: [
                      py, "-m", "fusion.evaluation", str(out / "pairs_demo"), "--methods",
                      "hybrid,grid,auto,paper_icp", "--out", str(out / "fusion_demo")],
                  _fusion_summary),
        DemoStage("bending", "6. Maps that bend: a drifting pair merged by the pose graph",
                  lambda out, steps: [py, str(examples / "bending.py"), "--out", str(out)],
                  _bending_summary),
    )


def _demo_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="topomerge demo",
        description="Run the demo's jobs (the paper's example, scripted episodes, a short PPO "
                    "run, map pairs from it, the fusion evaluation, maps that bend), each "
                    "one's output to OUT/logs/NAME.log, and print a short summary of each.")
    parser.add_argument("--out", type=Path, default=Path("out"), help="output folder (out)")
    parser.add_argument("--steps", type=int, default=DEMO_STEPS,
                        help=f"agent-steps of the PPO run ({DEMO_STEPS})")
    parser.add_argument("--only", default=None,
                        help="comma-separated stages to run "
                             "(paper,episode,train,dataset,fusion,bending)")
    return parser


def demo(argv: Sequence[str] | None = None) -> int:
    """Run the demo (see ``topomerge demo --help``); returns the exit status: 0, or the first
    failing job's (its log's last lines are printed)."""
    parser = _demo_parser()
    args = parser.parse_args(argv)
    if args.steps < 1:
        parser.error(f"--steps must be >= 1, got {args.steps}")
    stages = demo_stages()
    names = [s.name for s in stages]
    chosen = names if args.only is None else [n.strip() for n in args.only.split(",")]
    unknown = [n for n in chosen if n not in names]
    if unknown:
        parser.error(f"--only: unknown stage(s) {unknown}; choose from {names}")
    logs = args.out / "logs"
    logs.mkdir(parents=True, exist_ok=True)
    if "dataset" in chosen:  # a dataset folder refuses a different run's settings
        import shutil

        shutil.rmtree(args.out / "pairs_demo", ignore_errors=True)
    started = time.perf_counter()
    for stage in (s for s in stages if s.name in chosen):
        log = logs / f"{stage.name}.log"
        t0 = time.perf_counter()
        with open(log, "w", encoding="utf-8") as fh:
            done = subprocess.run(stage.argv(args.out, args.steps), stdout=fh,
                                  stderr=subprocess.STDOUT, env=_child_env(), check=False)
        text = log.read_text(encoding="utf-8", errors="replace")
        print(f"\n{stage.title} ({time.perf_counter() - t0:.0f} s, log {log})", flush=True)
        if done.returncode != 0:
            print("\n".join(f"  {r}" for r in text.splitlines()[-15:]))
            print(f"  FAILED with exit status {done.returncode}: see {log}")
            return done.returncode
        for line in stage.summary(args.out, text):
            print(f"  {line}")
    summary = {"seconds": round(time.perf_counter() - started, 1), "stages": chosen,
               "logs": str(logs)}
    (logs / "summary.json").write_text(json.dumps(summary, indent=2) + "\n", encoding="utf-8")
    print(f"\ndone in {summary['seconds']:.0f} s; every job's full output is in {logs}/")
    return 0


# --- dispatch ---------------------------------------------------------------------------------

COMMANDS: dict[str, tuple[str, Callable[[list[str]], int]]] = {
    "demo": ("run the demo's jobs and print a short summary", demo),
    "dataset": ("generate or inspect map-pair datasets (generate | info)", _dataset),
    "evaluate": ("evaluate merge methods on map pairs (python -m fusion.evaluation)", _evaluate),
    "calibrate": ("refit the merges' calibrated confidences (python -m fusion.calibration)",
                  _calibrate),
    "merge": ("merge robots' saved ROS maps into one (python -m fusion merge)", _merge),
    "train": ("train a PPO exploration policy (python train.py)", _train),
    "bench": ("run a benchmark script by name (benchmarks/NAME.py)", _bench),
}
"""Subcommand → (one-line help, runner taking the remaining arguments)."""


def _parser() -> argparse.ArgumentParser:
    lines = "\n".join(f"  {name:<10} {text}" for name, (text, _) in COMMANDS.items())
    return argparse.ArgumentParser(
        prog="topomerge", formatter_class=argparse.RawDescriptionHelpFormatter,
        usage="topomerge [-h] [--version] COMMAND [ARGS ...]",
        description="Multi-robot exploration with topological map fusion.",
        epilog=f"commands:\n{lines}\n\n'topomerge COMMAND --help' shows a command's options.")


def main(argv: Sequence[str] | None = None) -> int:
    """Dispatch ``argv`` (default ``sys.argv[1:]``) to its command; returns the exit status.
    An unknown command exits with status 2 and names the valid ones."""
    args = list(sys.argv[1:] if argv is None else argv)
    parser = _parser()
    if not args or args[0] in ("-h", "--help"):
        parser.print_help()
        return 0 if args else 2
    if args[0] == "--version":
        from importlib.metadata import PackageNotFoundError, version

        try:
            print(f"topomerge {version('topomerge')}")
        except PackageNotFoundError:
            print("topomerge (not installed: running from the source tree)")
        return 0
    if args[0] not in COMMANDS:
        parser.error(f"unknown command {args[0]!r}; choose from {', '.join(COMMANDS)}")
    return COMMANDS[args[0]][1](args[1:])


if __name__ == "__main__":
    sys.exit(main())

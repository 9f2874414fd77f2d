"""agents.workers: a dataset run's worker processes die with it and write nothing without its
lock."""

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest

from agents.workers import WATCH_S, RunGone, alive, check_owner, set_owner
from fusion.evaluation.pairs import LOCK_FILE
from topo.fileio import exclusive_lock

ROOT = Path(__file__).parents[2]


def descendants(pid: int) -> set[int]:
    """Every process below ``pid`` (from /proc)."""
    children: dict[int, list[int]] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            ppid = int(stat.read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        children.setdefault(ppid, []).append(int(stat.parent.name))
    out, todo = set(), [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            out.add(child)
            todo.append(child)
    return out


def written(out: Path) -> list[str]:
    folder = out / "pairs"
    return sorted(p.name for p in folder.iterdir()) if folder.is_dir() else []


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads the process tree from /proc")
def test_workers_die_with_a_killed_run_and_write_nothing_more(tmp_path):
    out = tmp_path / "d"
    run = subprocess.Popen(
        # far more pairs than get written before the kill: the run is still busy then (20
        # pairs took 5 s on 2 CPUs, and the check came 3 s after the pool started)
        [sys.executable, "-m", "agents.dataset", "generate", "--pairs", "400", "--out", str(out),
         "--workers", "2", "--max-cycles", "400", "--world-size", "10", "10", "--no-progress"],
        cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)}, start_new_session=True,
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 180
        while len(descendants(run.pid)) < 3 and time.monotonic() < deadline:  # tracker, workers
            time.sleep(0.2)
        time.sleep(3.0)  # the workers are into their episodes
        workers = descendants(run.pid)
        assert len(workers) >= 3, "the pool did not start"
    finally:
        run.send_signal(signal.SIGKILL)
        run.wait(timeout=30)
    gone_by = time.monotonic() + 5.0
    while any(alive(p) for p in workers) and time.monotonic() < gone_by:
        time.sleep(0.1)
    left = [p for p in workers if alive(p)]
    for p in left:  # do not leave them running whatever the verdict
        os.kill(p, signal.SIGKILL)
    assert left == [], f"workers {left} outlived their run"
    before = written(out)
    time.sleep(2 * WATCH_S + 1.0)
    assert written(out) == before


def test_a_worker_writes_only_while_its_run_holds_the_lock(tmp_path):
    host, lock = socket.gethostname(), str(tmp_path / LOCK_FILE)
    try:
        set_owner((os.getpid(), host, lock))
        with pytest.raises(RunGone, match=r"no longer holds .*\.lock: nothing written"):
            check_owner()  # no lock at all
        with exclusive_lock(lock):
            check_owner()  # held by its run: fine
            set_owner((os.getpid() + 1, host, lock))  # another run holds it
            with pytest.raises(RunGone, match=rf"pid {os.getpid() + 1} on "):
                check_owner()
        dead = subprocess.run([sys.executable, "-c", "import os; print(os.getpid())"],
                              capture_output=True, text=True, check=True)
        pid = int(dead.stdout)
        (tmp_path / LOCK_FILE).write_text(f'{{"pid": {pid}, "host": "{host}"}}')
        set_owner((pid, host, lock))  # the file names the run, but it died (kill -9 leaves it)
        with pytest.raises(RunGone):
            check_owner()
    finally:
        set_owner(None)
    check_owner()  # the run's own process needs no check

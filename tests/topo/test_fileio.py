"""topo.fileio.atomic_write_dir: a folder appears whole, replaces the old one, or not at all."""

import os

import pytest

from topo import fileio
from topo.fileio import TEMP_PREFIX, atomic_write_dir


def test_a_folder_is_written_and_replaces_the_old_one(tmp_path):
    target = tmp_path / "sub" / "ckpt"

    def write(folder, text):
        (folder / "a.txt").write_text(text)
        (folder / "inner").mkdir()

    assert atomic_write_dir(target, lambda f: write(f, "one")) == target
    assert (target / "a.txt").read_text() == "one" and (target / "inner").is_dir()
    atomic_write_dir(target, lambda f: write(f, "two"))
    assert (target / "a.txt").read_text() == "two"
    assert [p.name for p in target.parent.iterdir()] == ["ckpt"]  # no temporaries left


def test_a_failed_write_leaves_the_old_folder_and_no_temporary(tmp_path):
    target = tmp_path / "ckpt"
    atomic_write_dir(target, lambda f: (f / "a.txt").write_text("old"))

    def fail(folder):
        (folder / "a.txt").write_text("half")
        raise RuntimeError("disk full")

    with pytest.raises(RuntimeError, match="disk full"):
        atomic_write_dir(target, fail)
    assert (target / "a.txt").read_text() == "old"
    assert not [p for p in tmp_path.iterdir() if p.name.startswith(TEMP_PREFIX)]


def test_a_failed_move_into_place_puts_the_old_folder_back(tmp_path, monkeypatch):
    """The old folder is moved aside before the new one moves in; if that second rename fails
    the old one returns to its place."""
    target = tmp_path / "ckpt"
    atomic_write_dir(target, lambda f: (f / "a.txt").write_text("old"))
    real = os.replace

    def replace(src, dst):
        if str(src).startswith(str(tmp_path / TEMP_PREFIX)) and "old-" not in str(src):
            raise OSError("rename failed")
        return real(src, dst)

    monkeypatch.setattr(fileio.os, "replace", replace)
    with pytest.raises(OSError, match="rename failed"):
        atomic_write_dir(target, lambda f: (f / "a.txt").write_text("new"))
    assert (target / "a.txt").read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == ["ckpt"]


def test_json_lines_round_trip_and_a_missing_file_is_empty(tmp_path):
    from topo.fileio import atomic_write_json_lines, read_json_lines

    path = tmp_path / "rows.jsonl"
    assert read_json_lines(path) == []
    rows = [{"b": 1, "a": [1.5, None]}, {"c": "x"}]
    atomic_write_json_lines(path, rows, sort_keys=True)
    assert path.read_text().splitlines()[0] == '{"a": [1.5, null], "b": 1}'
    assert read_json_lines(path) == rows
    (tmp_path / "list.json").write_text('[{"a": 1}, {"a": 2}]')
    assert read_json_lines(tmp_path / "list.json") == [{"a": 1}, {"a": 2}]
    with pytest.raises(ValueError, match="Out of range float values"):
        atomic_write_json_lines(path, [{"a": float("nan")}], allow_nan=False)
    assert read_json_lines(path) == rows  # a refused write leaves the file as it was

"""coop_gym.io: atomic writes leave the old file or the new one, never a partial or temporary file."""

from __future__ import annotations

import errno
import json
import os
import threading
from pathlib import Path

import pytest

from coop_gym import io as atomic_io


def _disk_full_after_write(path: Path) -> None:
    """Stand-in for ``_fsync`` on a full disk: the bytes are written, then flushing them fails."""
    assert path.exists() and atomic_io.TEMP_MARKER in path.name  # the partial file is on disk now
    raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))


def test_writers_replace_the_target_and_leave_no_temporary(tmp_path):
    atomic_io.write_text(tmp_path / "a.txt", "one")
    atomic_io.write_text(tmp_path / "a.txt", "two")
    atomic_io.write_bytes(tmp_path / "b.bin", b"\x00\x01")
    atomic_io.write_json(tmp_path / "c.json", {"k": [1, 2]})
    with atomic_io.atomic_open(tmp_path / "d.csv", "w", newline="") as handle:
        handle.write("x,y\n")
    assert (tmp_path / "a.txt").read_text() == "two"
    assert json.loads((tmp_path / "c.json").read_text()) == {"k": [1, 2]}
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "b.bin", "c.json", "d.csv"]


def test_figure_keeps_its_format(tmp_path):
    from matplotlib.figure import Figure

    fig = Figure()
    fig.subplots().plot([0, 1])
    atomic_io.save_figure(fig, tmp_path / "f.png")
    assert (tmp_path / "f.png").read_bytes()[:4] == b"\x89PNG"
    assert [p.name for p in tmp_path.iterdir()] == ["f.png"]


def test_full_disk_keeps_the_old_file_and_leaves_no_partial(tmp_path, monkeypatch):
    target = tmp_path / "results.json"
    atomic_io.write_json(target, {"old": True})
    monkeypatch.setattr(atomic_io, "_fsync", _disk_full_after_write)
    with pytest.raises(OSError) as exc:
        atomic_io.write_json(target, {"new": True})
    assert exc.value.errno == errno.ENOSPC
    assert json.loads(target.read_text()) == {"old": True}
    assert [p.name for p in tmp_path.iterdir()] == ["results.json"]


def test_an_error_inside_the_writer_removes_the_temporary(tmp_path):
    with pytest.raises(RuntimeError), atomic_io.atomic_open(tmp_path / "x.txt") as handle:
        handle.write("half")
        raise RuntimeError("writer failed")
    assert not any(tmp_path.iterdir())


def test_atomic_open_refuses_append():
    with pytest.raises(ValueError, match="mode"), atomic_io.atomic_open("x.txt", "a"):
        pass


def test_unique_folders_never_collide_and_have_no_ceiling(tmp_path):
    for k in range(1, 120):
        (tmp_path / f"run_{k}").mkdir()
    made: list[Path] = []
    threads = [
        threading.Thread(target=lambda: made.append(atomic_io.make_unique_folder(tmp_path, "run"))) for _ in range(8)
    ]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    assert len({p.name for p in made}) == 8
    assert "run" in {p.name for p in made} and "run_120" in {p.name for p in made}

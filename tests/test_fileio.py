import json
import os
import stat

import numpy as np
import pytest

from quad_envs.fileio import write_csv, write_json


def test_files_are_readable_by_others_and_follow_the_umask(tmp_path):
    old = os.umask(0o022)
    try:
        path = write_json(tmp_path / "a.json", {"x": 1})
        csv = write_csv(tmp_path / "b.csv", ["t"], np.zeros((2, 1)))
    finally:
        os.umask(old)
    for p in (path, csv):
        assert stat.S_IMODE(p.stat().st_mode) == 0o644
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".")] == []  # no leftovers


def test_json_is_strict_nan_and_inf_become_null(tmp_path):
    path = write_json(
        tmp_path / "m.json", {"a": float("nan"), "b": [np.inf, np.float64(2.5)], "c": np.arange(2)}
    )
    text = path.read_text()
    assert "NaN" not in text and "Infinity" not in text
    assert json.loads(text) == {"a": None, "b": [None, 2.5], "c": [0, 1]}


def test_unwritable_targets_raise_one_line_errors(tmp_path):
    with pytest.raises(ValueError, match="is a directory"):
        write_json(tmp_path, {})
    not_a_folder = tmp_path / "file.txt"
    not_a_folder.write_text("")
    with pytest.raises(ValueError, match="cannot write"):
        write_json(not_a_folder / "x.json", {})


def test_a_link_is_written_through_and_special_files_are_refused_not_replaced(tmp_path):
    """Renaming onto a path replaces whatever is there: a user's symbolic link became a plain
    file (its target unwritten), and a FIFO (as root, /dev/full) was replaced (a trial)."""
    target = tmp_path / "real.json"
    target.write_text("{}")
    link = tmp_path / "link.json"
    link.symlink_to(target)
    write_json(link, {"x": 1})
    assert link.is_symlink() and json.loads(target.read_text()) == {"x": 1}
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    with pytest.raises(ValueError, match="pipe is not a regular file"):
        write_json(fifo, {})
    assert stat.S_ISFIFO(fifo.stat().st_mode)


def test_a_replaced_file_keeps_its_permissions_and_a_read_only_one_is_kept(tmp_path):
    """A fuzz trial's 0444 model was replaced, and a 0600 one came back 0644."""
    private = write_json(tmp_path / "p.json", {"x": 1})
    private.chmod(0o600)
    write_json(private, {"x": 2})
    assert stat.S_IMODE(private.stat().st_mode) == 0o600 and json.loads(private.read_text()) == {
        "x": 2
    }
    locked = write_json(tmp_path / "r.json", {"x": 1})
    locked.chmod(0o444)
    with pytest.raises(ValueError, match="r.json is read-only"):
        write_json(locked, {"x": 2})
    assert json.loads(locked.read_text()) == {"x": 1}

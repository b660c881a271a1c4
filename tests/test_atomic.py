"""A file replaced whole: the old one or the new one, never half, and no temporary left."""

from __future__ import annotations

import os
import stat

import numpy as np
import pytest

from impctl.atomic import replacing


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


def test_the_new_file_replaces_the_old_and_nothing_else_is_left(tmp_path):
    target = tmp_path / "x.json"
    target.write_text("old")
    with replacing(target, fsync=True) as tmp:
        assert tmp.parent == tmp_path and tmp != target
        tmp.write_text("new")
        assert target.read_text() == "old"    # not visible before the block ends
    assert target.read_text() == "new"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]


def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path):
    target = tmp_path / "x.json"
    target.write_text("old")
    with pytest.raises(OSError, match="No space left"):
        with replacing(target) as tmp:
            tmp.write_text("half")
            raise OSError(28, "No space left on device")
    assert target.read_text() == "old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["x.json"]


def test_a_new_target_is_created_and_a_failure_creates_none(tmp_path):
    with pytest.raises(KeyboardInterrupt):
        with replacing(tmp_path / "a.txt") as tmp:
            tmp.write_text("x")
            raise KeyboardInterrupt
    assert list(tmp_path.iterdir()) == []
    with replacing(tmp_path / "b.txt") as tmp:
        tmp.write_text("y")
    assert (tmp_path / "b.txt").read_text() == "y"


def test_permissions_exact_when_given_else_the_umask(tmp_path):
    old = os.umask(0o077)
    try:
        with replacing(tmp_path / "shared.json", mode=0o644) as tmp:
            tmp.write_text("{}")
        with replacing(tmp_path / "private.csv", mode=0o600) as tmp:
            tmp.write_text("a")
        with replacing(tmp_path / "default.txt") as tmp:
            tmp.write_text("b")
    finally:
        os.umask(old)
    assert _mode(tmp_path / "shared.json") == 0o644     # readable by others whatever the umask
    assert _mode(tmp_path / "private.csv") == 0o600
    assert _mode(tmp_path / "default.txt") == 0o600     # 0o666 less the umask 0o077


def test_a_writer_that_appends_its_own_ending_gets_the_suffix_it_needs(tmp_path):
    target = tmp_path / "forests.npz"
    with replacing(target, suffix=".tmp.npz") as tmp:
        np.savez(tmp, a=np.arange(3))    # np.savez would add .npz to any other name
    with np.load(target) as z:
        assert z["a"].tolist() == [0, 1, 2]
    assert sorted(p.name for p in tmp_path.iterdir()) == ["forests.npz"]

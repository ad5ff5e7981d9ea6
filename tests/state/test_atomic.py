"""Atomic writes: all or nothing, no temp files left behind."""

import os

import pytest

from demcli.errors import StateError
from demcli.state import atomic_path, atomic_write_text, read_state, write_state
from demcli.state.atomic import temp_path_for
from demcli.state.fields import example_state


def test_success_replaces_and_leaves_no_temp(tmp_path):
    # Given an existing file
    path = tmp_path / "out.csv"
    path.write_text("old\n")
    # When it is rewritten atomically
    atomic_write_text(path, "new\n")
    # Then it holds the new text and the folder holds nothing else
    assert path.read_text() == "new\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.csv"]


def test_writer_raising_midway_keeps_old_file(tmp_path):
    # Given an existing file
    path = tmp_path / "out.txt"
    path.write_text("old\n")
    # When a writer fails after writing half of its data
    with pytest.raises(RuntimeError, match="boom"):
        with atomic_path(path) as tmp:
            tmp.write_text("half of the ne")
            assert tmp.name == f".out.txt.tmp-{os.getpid()}"
            raise RuntimeError("boom")
    # Then the old file is intact and the temp file is gone
    assert path.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["out.txt"]


def test_interrupt_removes_temp(tmp_path):
    # Given a writer interrupted by Ctrl-C
    path = tmp_path / "x.bin"
    with pytest.raises(KeyboardInterrupt):
        with atomic_path(path) as tmp:
            tmp.write_bytes(b"partial")
            raise KeyboardInterrupt
    # Then nothing is left
    assert not path.exists() and not temp_path_for(path).exists()


def test_state_write_failing_midway_keeps_old_state(tmp_path):
    # Given a good state file on disk
    path = tmp_path / "02-compaction.h5"
    good = example_state()
    write_state(path, good)
    before = path.read_bytes()
    # When a later write fails inside h5py writing (an attribute that cannot be stored,
    # reached after the datasets of earlier groups were written)
    bad = example_state(seed=3)
    bad.group_attrs["spheres"] = {"oops": {"not": "storable"}}
    with pytest.raises(StateError, match="cannot store a dict"):
        write_state(path, bad)
    # Then the old file is byte-for-byte intact, still readable, and no temp file remains
    assert path.read_bytes() == before
    assert read_state(path) == good
    assert [p.name for p in tmp_path.iterdir()] == ["02-compaction.h5"]


def test_creates_parent_folder(tmp_path):
    path = tmp_path / "runs" / "case" / "records" / "e.csv"
    atomic_write_text(path, "a\n")
    assert path.read_text() == "a\n"
    assert sorted(p.name for p in path.parent.iterdir()) == ["e.csv"]

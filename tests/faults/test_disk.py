"""A full disk or a read-only output folder ends a run with one line naming the path and the
cause (exit 1 or 2), never a traceback or a crash, and every state file left is whole (#27
item 9).

As root (CI) the disk is a real one: a small tmpfs, or one mounted read-only. Without root
the same faults come from the kernel otherwise: RLIMIT_FSIZE (each write past the limit
fails with EFBIG) and a folder without write permission.
"""

import os
import resource
import signal
import subprocess
import sys
from contextlib import contextmanager
from pathlib import Path

import h5py
import pytest

ROOT = Path(__file__).resolve().parents[2]
CASE = ROOT / "cases" / "smoke" / "beads.yaml"
ROOT_USER = os.geteuid() == 0


@contextmanager
def small_disk(folder, size_kib, file_kib=None, read_only=False):
    """``folder`` as a disk of ``size_kib`` KiB (tmpfs, as root) or, without root, as itself;
    yields the per-file size limit [bytes] to apply to the child then (``file_kib``)."""
    folder.mkdir(parents=True, exist_ok=True)
    if ROOT_USER:
        opts = f"size={size_kib}k" + (",ro" if read_only else "")
        subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(folder)], check=True)
        try:
            yield None
        finally:
            subprocess.run(["umount", str(folder)], check=True)
    else:
        if read_only:
            folder.chmod(0o555)
        try:
            yield None if read_only else file_kib * 1024
        finally:
            folder.chmod(0o755)


def _limited(limit):
    """preexec_fn: every file write beyond ``limit`` bytes fails with EFBIG (not a signal)."""
    def set_limit():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return set_limit


def _demcli_run(out, limit=None):
    return subprocess.run([sys.executable, "-m", "demcli", "run", str(CASE), "--out", str(out), "--quiet"],
                          capture_output=True, text=True, timeout=600, cwd=ROOT,
                          preexec_fn=_limited(limit) if limit else None)


def _one_clean_error_line(proc, path_part, causes):
    err = proc.stderr
    assert proc.returncode in (1, 2), (proc.returncode, err)  # not a crash (139 / -11), not success
    assert "Traceback" not in err and "Exception ignored" not in err and "Segmentation" not in err, err
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error: cannot write ") and path_part in lines[0], err
    assert any(c in lines[0] for c in causes), err


def _whole_states(folder):
    """Every .h5 left in the folder opens and has its meta group (atomic writes)."""
    for path in Path(folder).glob("*.h5"):
        with h5py.File(path, "r") as f:
            assert "meta" in f, path
    assert not list(Path(folder).glob(".*.tmp-*")), "a temp file was left behind"


# disk sizes at which the beads case (about 300 KiB) runs out of room at different writes:
# the first state, a snapshot while stepping, a plot, the last state; without root, per-file
# limits that the first state (47 KiB), a plot (39 KiB) and the last state (81 KiB) exceed
@pytest.mark.parametrize("size_kib, file_kib", [(40, 30), (100, 45), (200, 38), (280, 60)])
def test_a_full_disk_ends_with_one_line_and_whole_states(tmp_path, size_kib, file_kib):
    disk = tmp_path / "disk"
    with small_disk(disk, size_kib, file_kib) as limit:
        proc = _demcli_run(disk / "run", limit)
        _one_clean_error_line(proc, str(disk / "run"), ("No space left on device", "File too large"))
        _whole_states(disk / "run")


def test_a_read_only_output_folder_is_refused_at_once(tmp_path):
    disk = tmp_path / "disk"
    with small_disk(disk, 1024, read_only=True):
        for out in (disk, disk / "run"):  # the folder itself, or a new folder in it
            proc = _demcli_run(out)
            assert proc.returncode == 2
            _one_clean_error_line(proc, str(out), ("Read-only file system", "Permission denied"))


def test_write_error_of_a_state_keeps_the_previous_file(tmp_path, monkeypatch):
    """A failing write (here ENOSPC injected into the bytes' write) leaves the earlier file as
    it was and no temp file."""
    import errno

    from demcli.errors import WriteError
    from demcli.state import atomic

    target = tmp_path / "a.h5"
    target.write_bytes(b"old")

    class Full:
        def __init__(self, *a, **k):
            pass

        def __enter__(self):
            return self

        def __exit__(self, *a):
            return False

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        flush = write

    monkeypatch.setattr(atomic, "open", Full, raising=False)
    with pytest.raises(WriteError, match="cannot write .*a.h5: No space left on device") as info:
        atomic.atomic_write_bytes(target, b"new")
    assert info.value.exit_code == 1
    assert target.read_bytes() == b"old" and list(tmp_path.iterdir()) == [target]

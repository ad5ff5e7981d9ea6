"""Exceptions that reach the user as a message, never as a traceback.

Exit codes: 2 for bad input (case file, state file, arguments), 1 for a run that
failed (instability, interruption).
"""

import errno

import click


class DemcliError(click.ClickException):
    """Base class: shown as ``Error: <message>`` with the class's exit code."""

    exit_code = 1

    def show(self, file=None):
        click.echo(f"Error: {self.format_message()}", err=True)


class InputError(DemcliError):
    """Bad input of any kind; exit code 2."""

    exit_code = 2


class ConfigError(InputError):
    """A case file that fails validation. ``errors`` holds every problem found."""

    def __init__(self, errors):
        self.errors = list(errors)
        lines = [str(e) for e in self.errors]
        head = "1 problem" if len(lines) == 1 else f"{len(lines)} problems"
        super().__init__(f"invalid case ({head}):\n  " + "\n  ".join(lines))


class StateError(InputError):
    """A state (HDF5) file that is missing, corrupt, foreign or of another schema version."""


class StageError(DemcliError):
    """A stage that could not finish (instability, interruption); exit code 1."""

    def __init__(self, message, state_file=None):
        self.state_file = state_file
        if state_file is not None:
            message = f"{message}\n  last good state kept in {state_file}"
        super().__init__(message)


# errors of the disk rather than of the program: a full disk or quota, a read-only folder
DISK_ERRNOS = {errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EROFS, errno.EACCES, errno.EPERM, errno.EIO}


class WriteError(DemcliError):
    """A file that cannot be written (full disk, quota, read-only or forbidden folder): one
    line naming the path and the cause. Exit code 2 for a folder the user cannot write to
    (read-only, permission), 1 for a disk that ran out of room or failed."""

    def __init__(self, path, exc):
        self.path = path
        self.errno = exc.errno
        if exc.errno in (errno.EROFS, errno.EACCES, errno.EPERM):
            self.exit_code = 2
        super().__init__(f"cannot write {path}: {exc.strerror or exc}")

    @staticmethod
    def is_disk_error(exc):
        """Whether ``exc`` is an OSError of the disk (see ``DISK_ERRNOS``)."""
        return isinstance(exc, OSError) and exc.errno in DISK_ERRNOS

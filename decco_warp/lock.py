"""One writer per run folder: an OS lock held by the process that writes into it.

The lock is ``flock`` on the folder itself, so the kernel releases it when its holder dies in
any way (SIGKILL, power loss): nothing stale is left to clean.  While it holds the lock, the
writer keeps its pid and host in ``.lock`` in the folder, so that a refused second writer can
say who holds it.  (flock is local to a machine: on a network file system shared by several
hosts, run a given folder from one host at a time.)
"""

from __future__ import annotations

import contextlib
import fcntl
import os
import socket
from pathlib import Path

from .checks import InputError

LOCK_FILE = ".lock"


class RunFolderBusy(InputError):
    """Another process writes into this run folder."""


class _Lock:
    """``with``: acquire on entry, release on exit."""

    def __enter__(self):
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()


class RunFolderLock(_Lock):
    """The exclusive lock of one run folder; ``acquire`` raises RunFolderBusy if it is held."""

    def __init__(self, run_dir):
        self.run_dir = Path(run_dir)
        self._fd: int | None = None
        self._noted = False

    @property
    def held(self) -> bool:
        return self._fd is not None

    def acquire(self, note: bool = True) -> "RunFolderLock":
        """Take the lock (``note``: and write this process's pid and host beside it)."""
        if self.held:
            return self
        fd = os.open(self.run_dir, os.O_RDONLY)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            os.close(fd)
            pid, host = holder(self.run_dir)
            raise RunFolderBusy(f"run folder {self.run_dir} is in use by pid {pid} on {host}") from None
        self._fd = fd
        self._noted = note
        if note:
            try:  # only says who holds the lock (the flock is the lock): a full disk need not stop the work
                (self.run_dir / LOCK_FILE).write_text(f"{os.getpid()} {socket.gethostname()}\n")
            except OSError:
                self._noted = False
        return self

    def release(self) -> None:
        if self._fd is None:
            return
        if self._noted:
            with contextlib.suppress(OSError):
                (self.run_dir / LOCK_FILE).unlink()
        os.close(self._fd)
        self._fd = None


def holder(run_dir) -> tuple[str, str]:
    """(pid, host) written by the process holding the lock, or ("?", "?") when unreadable."""
    try:
        pid, host = (Path(run_dir) / LOCK_FILE).read_text().split()[:2]
        return pid, host
    except (OSError, ValueError):
        return "?", "?"


def ensure_free(run_dir) -> None:
    """Raise RunFolderBusy if a process holds ``run_dir``'s lock (a folder that does not exist is free)."""
    if Path(run_dir).is_dir():
        RunFolderLock(run_dir).acquire(note=False).release()


ANALYSIS_LOCK_FILE = ".analysis.lock"


class AnalysisLock(_Lock):
    """The lock of one run folder's analysis, apart from its writer's: two analyses of a run
    exclude each other, while the run itself may still be writing its trajectory.

    The lock is ``flock`` on ``.analysis.lock`` in the folder, which holds its holder's pid and
    host and is removed on release (a holder checks that the file it locked is still the one
    named so, since a release may remove it in between)."""

    def __init__(self, run_dir):
        self.run_dir = Path(run_dir)
        self.path = self.run_dir / ANALYSIS_LOCK_FILE
        self._fd: int | None = None

    def acquire(self) -> "AnalysisLock":
        while self._fd is None:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                text = os.pread(fd, 200, 0).decode(errors="replace").split()
                os.close(fd)
                pid, host = (text + ["?", "?"])[:2]
                raise RunFolderBusy(f"run folder {self.run_dir} is being analysed by pid {pid} on {host}") from None
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if not same:  # released and removed by its holder while this one waited: try again
                os.close(fd)
                continue
            with contextlib.suppress(OSError):  # only says who holds it: a full disk need not stop the work
                os.ftruncate(fd, 0)
                os.pwrite(fd, f"{os.getpid()} {socket.gethostname()}\n".encode(), 0)
            self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is None:
            return
        with contextlib.suppress(OSError):
            self.path.unlink()
        os.close(self._fd)
        self._fd = None


def ensure_not_analysed(run_dir) -> None:
    """Raise RunFolderBusy if another process is analysing ``run_dir``."""
    if Path(run_dir).is_dir():
        AnalysisLock(run_dir).acquire().release()

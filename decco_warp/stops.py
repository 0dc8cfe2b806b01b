"""Stops that wait for a safe point: while active, SIGINT (Ctrl-C) and SIGTERM (a batch scheduler's
stop) are noted instead of ending the process, so that long work (a run, a forming pile) can save
a checkpoint first and then end.  A run stepped for a sweep on a Dask worker (a thread, which
signals never reach) is asked to stop through a file instead: the sweep writes the signal's name
into it (:func:`request_stop`), and the run's loop reads it where it would read a signal.

:func:`drive` is that loop, the one of runs, ensembles of runs and forming piles."""

from __future__ import annotations

import signal
import threading
import time
from pathlib import Path
from typing import Protocol


class StopRequests:
    """While active, SIGINT and SIGTERM are noted instead of killing the process.  ``signal`` is the
    first one noted, or the name in ``request_file`` once that exists (None: go on); ``count`` the
    signals noted."""

    def __init__(self, request_file=None):
        self.noted: str | None = None
        self.count = 0
        self.request_file = Path(request_file) if request_file is not None else None
        self._previous: dict = {}

    @property
    def signal(self) -> str | None:
        if self.noted is None and self.request_file is not None:
            try:
                return self.request_file.read_text().strip() or "SIGINT"
            except OSError:  # none asked for (or not readable just now: looked at again soon)
                return None
        return self.noted

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for number in (signal.SIGINT, signal.SIGTERM):
                self._previous[number] = signal.signal(number, self._note)
        return self

    def _note(self, number, frame) -> None:
        self.noted = self.noted or signal.Signals(number).name
        self.count += 1

    def __exit__(self, *exc) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)


class Stepping(Protocol):
    """What :func:`drive` steps: a run (run.RunDriver), runs stepped together, a forming pile."""

    @property
    def done(self) -> bool: ...

    def advance(self) -> None:
        """Step a chunk: up to the next stop (a frame, a checkpoint, a report), or one batch."""

    def after(self, seconds: float, stop: StopRequests) -> None:
        """What is due after ``seconds`` of stepping (frames, checkpoints, progress); where ``stop.signal``
        is read (once, where it says), the save that a stop asks for and the typed error that ends the work."""


def drive(stepping: Stepping, request_file=None) -> None:
    """Step ``stepping`` in chunks until it is done, the stops (Ctrl-C, SIGTERM, ``request_file``)
    noted and handed to it after each chunk, its safe point."""
    with StopRequests(request_file) as stop:
        while not stepping.done:
            began = time.perf_counter()
            stepping.advance()
            stepping.after(time.perf_counter() - began, stop)


def request_stop(request_file, signal_name: str) -> None:
    """Ask the runs that watch ``request_file`` to stop at their next safe point, as ``signal_name`` would."""
    Path(request_file).write_text(signal_name)


def clear_request(request_file) -> None:
    """Withdraw a stop request (one left by a sweep that was killed, say)."""
    Path(request_file).unlink(missing_ok=True)


def ignore_stops() -> None:
    """In a helper process (a sweep's worker, an analysis process) that shares the terminal of its
    parent: leave SIGINT and SIGTERM to the parent, which stops the work in order.  The terminal's
    Ctrl-C reaches every process of its group at once; a worker that died of it would lose the work
    of its run since the last checkpoint."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_IGN)

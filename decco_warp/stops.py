"""Stops that wait for a safe point: while active, SIGINT (Ctrl-C) and SIGTERM (a batch scheduler's
stop) are noted instead of ending the process, so that long work (a run, a forming pile) can save
a checkpoint first and then end."""

from __future__ import annotations

import signal
import threading


class StopRequests:
    """While active, SIGINT and SIGTERM are noted instead of killing the process."""

    def __init__(self):
        self.signal: str | None = None
        self._previous: dict = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for number in (signal.SIGINT, signal.SIGTERM):
                self._previous[number] = signal.signal(number, self._note)
        return self

    def _note(self, number, frame) -> None:
        self.signal = signal.Signals(number).name

    def __exit__(self, *exc) -> None:
        for number, handler in self._previous.items():
            signal.signal(number, handler)

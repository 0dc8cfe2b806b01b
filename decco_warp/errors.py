"""Every error decco-warp raises on purpose, under one base class.

    try:
        dw.Simulation(state, params)
    except dw.DeccoError as error:     # any of them: error.line is its one line for a user,
        print(error.line)              # error.exit_code what `decco-warp` ends with

Each is also the built-in it always was (ValueError for input that cannot be used, RuntimeError
for a run that went wrong), so code catching those still catches them.  Subclasses exist where a
caller must tell them apart; module-specific ones (analysis/compare.py's CompareError family,
lock.py's RunFolderBusy) derive from these.  Nothing here imports the package.
"""

from __future__ import annotations

from pathlib import Path

#: Exit codes of the `decco-warp` command (cli.py re-exports them).
EXIT_FAILED = 1  # a job that could not finish as asked (a pile that did not settle)
EXIT_INPUT = 2  # bad input: nothing was run or written
EXIT_STOPPED = 3  # SIGINT/SIGTERM: checkpoint written, resumable
EXIT_BLOW_UP = 4  # non-finite values or runaway overlaps: the last good checkpoint is kept
EXIT_OUTPUT = 5  # writing the run folder failed (disk full): the last checkpoint is intact
EXIT_NOT_SETTLED = 6  # resume --until-settled reached its step limit with the outcome still changing: the run is whole


class DeccoError(Exception):
    """Base of decco-warp's errors: ``line`` is the message's first line, ``exit_code`` the code
    the command ends with."""

    exit_code = EXIT_INPUT

    @property
    def line(self) -> str:
        text = str(self).strip().splitlines()
        return text[0] if text else type(self).__name__


# --- bad input: nothing was run or written (exit 2) --------------------------------------------


class InputError(DeccoError, ValueError):
    """Input that cannot be used as it is: the message says which value and why."""


class SpecError(DeccoError, ValueError):
    """A run specification that cannot be run as written."""


class RunError(DeccoError, ValueError):
    """A run that cannot start or continue as asked (bad folder, pile, checkpoint)."""


class FileFormatError(DeccoError, ValueError):
    """A file that is missing, unreadable, or not what it claims to be."""


class DeviceError(DeccoError, ValueError):
    """A device name that is malformed or not present on this machine."""


class StabilityError(DeccoError, ValueError):
    """A set-up that violates eq. 15 or 17; ``.report`` holds the numbers (stability.StabilityReport)."""

    def __init__(self, report):
        self.report = report
        super().__init__("unstable set-up: " + "; ".join(report.problems()))


class RerunUnavailable(DeccoError, RuntimeError):
    """rerun-sdk is not installed (or failed to import)."""


# --- a job that went wrong -----------------------------------------------------------------------


class FormationError(DeccoError, RuntimeError):
    """A pile that did not settle within the allowed number of steps."""

    exit_code = EXIT_FAILED


class BlowUp(DeccoError, RuntimeError):
    """The run went numerically wrong (non-finite values or spheres passing through each other)."""

    exit_code = EXIT_BLOW_UP


class OutputError(DeccoError, RuntimeError):
    """Writing the run folder failed (a full disk, a vanished folder); the last checkpoint is intact."""

    exit_code = EXIT_OUTPUT


class NotSettled(DeccoError, RuntimeError):
    """A run extended until settled reached its step limit with its outcome still changing; the run is whole."""

    exit_code = EXIT_NOT_SETTLED


# --- stopped on request: resumable (exit 3) --------------------------------------------------------


class RunStopped(DeccoError, RuntimeError):
    """SIGINT or SIGTERM arrived; the run wrote a checkpoint and can be resumed."""

    exit_code = EXIT_STOPPED

    def __init__(self, signal_name: str, step: int, run_dir: Path):
        self.signal_name, self.step, self.run_dir = signal_name, step, run_dir
        super().__init__(f"stopped by {signal_name} at step {step}, a checkpoint written; continue with: decco-warp resume {run_dir}")


class FormationStopped(DeccoError, RuntimeError):
    """SIGINT or SIGTERM arrived; the formation was saved and the same command continues it."""

    exit_code = EXIT_STOPPED

    def __init__(self, signal_name: str, step: int, partial: Path, timing: str = ""):
        self.signal_name, self.step, self.partial, self.timing = signal_name, step, partial, timing
        spent = f" (this session: {timing})" if timing else ""
        super().__init__(f"stopped by {signal_name} at step {step}; saved in {partial}: the same command continues{spent}")


class SweepStopped(DeccoError, RuntimeError):
    """SIGINT or SIGTERM arrived during a sweep: each run that was stepping wrote a checkpoint
    (``stopped``: their rows, with the step), those not started were left; ``unanalysed``: runs
    that had finished stepping but whose analysis had not begun (a sweep run again analyses them)."""

    exit_code = EXIT_STOPPED

    def __init__(self, signal_name: str, stopped: list[dict], unanalysed: list[str], at_once: bool = False):
        self.signal_name, self.stopped, self.unanalysed = signal_name, stopped, unanalysed
        self.at_once = at_once  # a second signal: the runs stepping were not waited for
        super().__init__(f"sweep stopped by {signal_name}")


class SchedulerLost(SweepStopped):
    """A sweep's Dask scheduler went away (stopped, its node lost): the runs finished are kept, those
    stepping keep their last periodic checkpoints; the same command continues once a scheduler is
    there again.  ``why``: what the client said."""

    def __init__(self, scheduler: str, why: str, stopped: list[dict], unanalysed: list[str]):
        self.scheduler, self.why = scheduler, why
        super().__init__("the scheduler's loss", stopped, unanalysed)

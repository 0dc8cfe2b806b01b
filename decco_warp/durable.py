"""Durable writes: files replaced atomically, strict JSON, the one hook every write passes through
(for the fault-injection tests), the room check before a frame, and what to do with an HDF5 file
whose write failed inside HDF5.

Nothing here knows a file format (decco_warp/io.py) or repairs a file (decco_warp/repair.py).
"""

from __future__ import annotations

import contextlib
import errno
import io as _io
import json
import math
import os
import tempfile
import threading
from pathlib import Path

import h5py
import numpy as np


def json_ready(value):
    """``value`` with NumPy scalars and arrays as Python numbers and lists, and every NaN or
    infinity as None: what strict JSON can hold (``null`` for a number that does not exist)."""
    if isinstance(value, dict):
        return {str(key): json_ready(item) for key, item in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [json_ready(item) for item in (value.tolist() if isinstance(value, np.ndarray) else value)]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def json_text(value) -> str:
    """Strict JSON (RFC 8259: no NaN, no Infinity) of ``value``, indented, with a final newline."""
    return json.dumps(json_ready(value), indent=2, allow_nan=False) + "\n"


def write_table(path, rows: list[dict], fieldnames: list[str], ignore_extra: bool = False) -> Path:
    """``rows`` as a CSV table with a header of ``fieldnames``, written atomically (:func:`write_atomic`:
    a failed write leaves the previous table whole); ``ignore_extra``: keys of a row outside
    ``fieldnames`` are left out instead of refused."""
    import csv

    table = _io.StringIO()
    writer = csv.DictWriter(table, fieldnames=fieldnames, extrasaction="ignore" if ignore_extra else "raise")
    writer.writeheader()
    writer.writerows(rows)
    return write_atomic(path, table.getvalue())


def write_atomic(path, data: bytes | str, what: str | None = None) -> Path:
    """Replace ``path`` with ``data`` atomically: a temporary file beside it, fsync, rename.

    A failed write (no space, an I/O error, the folder gone) raises OSError naming the file and
    leaves the previous file, if any, as it was; the folder is never created here."""
    path = Path(path)
    data = data.encode() if isinstance(data, str) else data
    write_point(what or path.name)
    handle, temporary = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.chmod(temporary, 0o666 & ~_umask())  # mkstemp made it private; give it the usual mode
        os.replace(temporary, path)
    except BaseException as error:
        with contextlib.suppress(OSError):
            os.unlink(temporary)
        if isinstance(error, OSError) and not error.filename:
            raise OSError(error.errno, error.strerror, str(path)) from None
        raise
    _fsync_directory(path.parent)
    return path


@contextlib.contextmanager
def atomic_h5(path: Path, **options):
    """Write an HDF5 file atomically: built in memory, then written whole (see :func:`write_atomic`);
    ``options`` go to h5py.File (``libver``, say).

    HDF5 never meets the disk here, so a full disk or an I/O error is one clean OSError and can
    never leave HDF5's own state broken (which can crash the process when the file is closed)."""
    buffer = _io.BytesIO()
    with h5py.File(buffer, "w", **options) as f:
        yield f
    write_atomic(path, buffer.getvalue())


# --- writes: the fault-injection hook, and files whose writer HDF5 gave up on ---------------

_writes = 0
_writes_lock = threading.Lock()
#: HDF5 files whose write failed inside HDF5: never closed (closing one can crash), kept from the
#: garbage collector; a process holding any ends with os._exit once it has said what happened.
ABANDONED: list = []


def write_point(what: str) -> None:
    """Every write of every command (a frame, a checkpoint, a log line, a figure, a table) passes
    here first.  Test hooks: DECCO_TEST_WRITES=FILE appends "k what" for the k-th write of the
    process; DECCO_TEST_FAIL_WRITE="k[:ENOSPC|:EIO]" fails the k-th write as a full disk (or an
    I/O error) would; DECCO_TEST_FULL=FILE fails every write as a full disk while FILE exists (a
    disk that fills, then is freed, under every process of a sweep at once)."""
    global _writes
    with _writes_lock:
        _writes += 1
        k = _writes
    journal = os.environ.get("DECCO_TEST_WRITES")
    if journal:
        with open(journal, "a", encoding="utf-8") as f:
            f.write(f"{k} {what}\n")
    full = os.environ.get("DECCO_TEST_FULL")
    if full and os.path.exists(full):
        raise outside_hdf5(OSError(errno.ENOSPC, f"{os.strerror(errno.ENOSPC)} (DECCO_TEST_FULL)", what))
    wanted = os.environ.get("DECCO_TEST_FAIL_WRITE")
    if wanted:
        index, _, kind = wanted.partition(":")
        if index.strip() == str(k):
            code = errno.EIO if kind.strip().upper() == "EIO" else errno.ENOSPC
            raise outside_hdf5(OSError(code, f"{os.strerror(code)} (DECCO_TEST_FAIL_WRITE)", what))


def outside_hdf5(error: OSError) -> OSError:
    """Mark a write error raised before HDF5 was called (a hook, the room check): HDF5's own state
    is whole, so the file may still be closed as usual."""
    error.outside_hdf5 = True
    return error


@contextlib.contextmanager
def complaints_held():
    """Hold what is printed to stderr during an HDF5 write, printed at the end unless ``drop`` is
    set: a write cut off inside HDF5 makes h5py print a traceback for every id it then fails to
    free, which the write's own one-line error already says.  (Lines printed meanwhile by other
    threads, a progress bar, are held with them.)"""
    import sys

    with _stderr_lock:
        real, held = sys.stderr, _io.StringIO()
        held.drop = False
        sys.stderr = held
        try:
            yield held
        finally:
            sys.stderr = real
            if not held.drop:
                real.write(held.getvalue())


_stderr_lock = threading.Lock()


def as_os_error(error: BaseException, what) -> OSError:
    """An HDF5 write error (h5py raises OSError or RuntimeError) as an OSError naming ``what``."""
    if isinstance(error, OSError) and error.errno:
        return OSError(error.errno, error.strerror, error.filename or str(what))
    text = str(error)
    for code in (errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.EROFS, errno.ENOENT):
        if f"errno = {code}," in text:
            return OSError(code, os.strerror(code), str(what))
    return OSError(errno.EIO, first_line(error), str(what))


def abandon(file) -> None:
    """Stop using an HDF5 file whose write failed inside HDF5, without closing it."""
    ABANDONED.append(file)


def describe_write_error(error: OSError) -> str:
    """"No space left on device writing trajectory.h5" from an OSError of a write."""
    what = f" writing {Path(error.filename).name}" if error.filename else ""
    return f"{error.strerror or first_line(error)}{what}"


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_directory(directory: Path) -> None:
    with contextlib.suppress(OSError):
        fd = os.open(directory, os.O_RDONLY)
        try:
            os.fsync(fd)
        finally:
            os.close(fd)


def first_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return text[0] if text else type(error).__name__


#: errno values of a write that failed for want of room or of a working disk or folder.
WRITE_ERRNOS = (errno.ENOSPC, errno.EIO, errno.EDQUOT, errno.EROFS, errno.ENOENT, errno.ESTALE)
#: Room a frame leaves free for HDF5's own metadata and the file's close [bytes].
FRAME_HEADROOM = 1 << 20


def check_space(folder: Path, frame_bytes: int, path: Path) -> None:
    """Raise ENOSPC before a frame that the disk has no room for: HDF5 cut off half-way through a
    frame can be left in a state that crashes at close; a frame refused here never starts."""
    try:
        stats = os.statvfs(folder)
    except OSError as error:  # the folder is gone
        raise outside_hdf5(OSError(error.errno, error.strerror, str(path))) from None
    if stats.f_bavail * stats.f_frsize < 2 * frame_bytes + FRAME_HEADROOM:
        raise outside_hdf5(OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path)))


def pause_point(phase: str, step: int) -> None:
    """Test hooks at the risky moments of a run (phases: step, trajectory-write, checkpoint-write).

    With DECCO_TEST_PAUSE="phase@step" the run stops here so that a test can kill it (or look
    at it), after creating the file named by DECCO_TEST_PAUSE_MARK, until that file is removed
    (forever without one); with
    DECCO_TEST_FAIL="phase@step" the write fails here as on a full disk.
    """
    here = f"{phase}@{step}"
    if os.environ.get("DECCO_TEST_FAIL") == here:
        raise outside_hdf5(OSError(errno.ENOSPC, "No space left on device (DECCO_TEST_FAIL)"))
    wanted = os.environ.get("DECCO_TEST_PAUSE")
    if not wanted or wanted != here:
        return
    mark = os.environ.get("DECCO_TEST_PAUSE_MARK")
    if mark:
        Path(mark).write_text(wanted)
    import time

    while not mark or Path(mark).exists():
        time.sleep(0.1)

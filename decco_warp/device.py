"""Which Warp device a run uses.

``device=None`` means the ``DECCO_DEVICE`` environment variable if set, else
CUDA when Warp finds a GPU, else the CPU.  An explicit device always wins.
"""

from __future__ import annotations

import os
import re
import sys
import tempfile

import warp as wp

from .errors import DeviceError  # noqa: F401 (re-exported: the error lives in errors.py)

ENV_VARIABLE = "DECCO_DEVICE"

# Warp's native library prints this on every start on a machine without an
# NVIDIA driver; running on the CPU there is normal, not worth a warning.
_NO_DRIVER_NOTICE = "Could not find or load the NVIDIA CUDA driver"


def init_warp() -> None:
    """Initialise Warp once, dropping only the no-driver notice from its native stderr."""
    if wp._src.context.runtime is not None:
        return
    sys.stderr.flush()
    saved = os.dup(2)
    with tempfile.TemporaryFile(mode="w+b") as captured:
        os.dup2(captured.fileno(), 2)
        try:
            wp.init()
        finally:
            os.dup2(saved, 2)
            os.close(saved)
        captured.seek(0)
        for line in captured.read().decode(errors="replace").splitlines():
            if _NO_DRIVER_NOTICE not in line:
                print(line, file=sys.stderr)


def cuda_device_count() -> int:
    init_warp()
    return wp.get_cuda_device_count()


def resolve_device(device: str | None = None) -> str:
    """Return a Warp device name ("cpu" or "cuda:N") for a user's choice.

    >>> resolve_device("cpu")
    'cpu'
    """
    init_warp()
    source = "device"
    if device is None:
        device = os.environ.get(ENV_VARIABLE) or None
        source = ENV_VARIABLE
    if device is None:
        return "cuda:0" if cuda_device_count() > 0 else "cpu"
    name = str(device).strip().lower()
    if name == "cpu":
        return "cpu"
    match = re.fullmatch(r"cuda(?::(\d+))?", name)
    if not match:
        raise DeviceError(f"{source} must be cpu, cuda or cuda:N; got {device!r}")
    index = int(match.group(1) or 0)
    count = cuda_device_count()
    if count == 0:
        raise DeviceError(f"{source} {device!r} asks for CUDA, but Warp finds no CUDA device here; use cpu")
    if index >= count:
        raise DeviceError(f"{source} {device!r}: there are only {count} CUDA device(s), cuda:0 to cuda:{count - 1}")
    return f"cuda:{index}"


def describe_devices() -> list[dict]:
    """Name, kind and (a GPU's) memory in bytes of every device Warp can use."""
    init_warp()
    return [
        {"name": d.alias, "description": d.name, "is_cuda": d.is_cuda, "memory": d.total_memory if d.is_cuda else None}
        for d in wp.get_devices()
    ]


def gpus_to_use(requested: int | None = None) -> int:
    """How many GPUs a local sweep uses, one worker pinned to each of cuda:0 to cuda:N-1:
    ``requested`` (checked against those visible), by default all of them (0 on a CPU)."""
    visible = cuda_device_count()
    if requested is None:
        return visible
    if requested < 1:
        raise DeviceError(f"--gpus {requested}: must be >= 1")
    if visible == 0:
        raise DeviceError(f"--gpus {requested}: Warp finds no GPU here; leave --gpus out to run on CPU workers (--workers)")
    if requested > visible:
        raise DeviceError(f"--gpus {requested}: only {visible} GPU(s) visible here, cuda:0 to cuda:{visible - 1}")
    return requested


def free_memory(device: str) -> int:
    """Bytes free on ``device`` now: a GPU's free memory, or the host's available memory for the CPU:
    psutil's ``available`` (the kernel's MemAvailable, which counts the file cache it can drop), not
    Warp's CPU figure, MemFree alone, a few hundred MB on a machine whose cache holds its files."""
    if not str(device).startswith("cuda"):
        import psutil  # a dependency of distributed

        return int(psutil.virtual_memory().available)
    init_warp()
    return int(wp.get_device(device).free_memory)


def gpu_uuid(device: str | None) -> str | None:
    """The UUID of the GPU ``device`` names in this process (None for the CPU): the same GPU has the
    same UUID in every process and on every host, whatever CUDA_VISIBLE_DEVICES calls it there."""
    if not device or not str(device).startswith("cuda"):
        return None
    init_warp()
    return str(wp.get_device(device).uuid)


def local_gpus() -> dict[str, str]:
    """This process's GPUs, UUID -> its name here ("cuda:N")."""
    init_warp()
    return {str(d.uuid): d.alias for d in wp.get_cuda_devices()}


def device_problem(device: str | None) -> str | None:
    """Why ``device`` cannot take work now (a GPU that is not there, or that fails a one-word
    allocation: one fallen off the bus, say), else None."""
    try:
        name = resolve_device(device)
        if name.startswith("cuda"):
            probe = wp.zeros(1, dtype=wp.int32, device=name)
            wp.synchronize_device(name)
            del probe
    except (DeviceError, RuntimeError) as error:
        return " ".join(str(error).split())
    return None

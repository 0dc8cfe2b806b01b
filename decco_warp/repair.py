"""Recovering an HDF5 file whose writer was killed: what ``h5clear -s`` does, in Python.

A file written in SWMR mode stays consistent if its writer is killed, but its superblock keeps the
writer's flags set; :func:`clear_write_flags` resets them (checking the superblock's checksum,
Jenkins' lookup3, first).
"""

from __future__ import annotations

import os
from pathlib import Path

HDF5_SIGNATURE = b"\x89HDF\r\n\x1a\n"


def _rotate(x: int, k: int) -> int:
    return ((x << k) | (x >> (32 - k))) & 0xFFFFFFFF


def lookup3(data: bytes, initval: int = 0) -> int:
    """Bob Jenkins' lookup3 hash (hashlittle), the checksum of HDF5 metadata."""
    mask = 0xFFFFFFFF
    length = len(data)
    a = b = c = (0xDEADBEEF + length + initval) & mask
    k = 0
    while length > 12:
        a = (a + int.from_bytes(data[k : k + 4], "little")) & mask
        b = (b + int.from_bytes(data[k + 4 : k + 8], "little")) & mask
        c = (c + int.from_bytes(data[k + 8 : k + 12], "little")) & mask
        a = (a - c) & mask; a ^= _rotate(c, 4); c = (c + b) & mask  # noqa: E702
        b = (b - a) & mask; b ^= _rotate(a, 6); a = (a + c) & mask  # noqa: E702
        c = (c - b) & mask; c ^= _rotate(b, 8); b = (b + a) & mask  # noqa: E702
        a = (a - c) & mask; a ^= _rotate(c, 16); c = (c + b) & mask  # noqa: E702
        b = (b - a) & mask; b ^= _rotate(a, 19); a = (a + c) & mask  # noqa: E702
        c = (c - b) & mask; c ^= _rotate(b, 4); b = (b + a) & mask  # noqa: E702
        length -= 12
        k += 12
    if length == 0:
        return c
    tail = data[k:].ljust(12, b"\0")
    a = (a + int.from_bytes(tail[0:4], "little")) & mask
    b = (b + int.from_bytes(tail[4:8], "little")) & mask
    c = (c + int.from_bytes(tail[8:12], "little")) & mask
    c ^= b; c = (c - _rotate(b, 14)) & mask  # noqa: E702
    a ^= c; a = (a - _rotate(c, 11)) & mask  # noqa: E702
    b ^= a; b = (b - _rotate(a, 25)) & mask  # noqa: E702
    c ^= b; c = (c - _rotate(b, 16)) & mask  # noqa: E702
    a ^= c; a = (a - _rotate(c, 4)) & mask  # noqa: E702
    b ^= a; b = (b - _rotate(a, 14)) & mask  # noqa: E702
    c ^= b; c = (c - _rotate(b, 24)) & mask  # noqa: E702
    return c


def clear_write_flags(path: Path) -> None:
    """What ``h5clear -s`` does: reset the superblock's "open for writing" flags.

    A file written in SWMR mode stays consistent if its writer is killed, but the
    writer's flags remain set and HDF5 then refuses to open it for writing.  Only
    a version 2/3 superblock at offset 0 whose checksum verifies is touched.
    """
    with open(path, "r+b") as f:
        head = f.read(48)
        if len(head) < 12 or head[:8] != HDF5_SIGNATURE or head[8] not in (2, 3) or head[11] == 0:
            return
        size = 12 + 4 * head[9]
        if int.from_bytes(head[size : size + 4], "little") != lookup3(head[:size]):
            return
        patched = head[:11] + b"\0" + head[12:size]
        f.seek(0)
        f.write(patched + lookup3(patched).to_bytes(4, "little"))
        f.flush()
        os.fsync(f.fileno())

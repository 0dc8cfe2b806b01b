"""How the all-pairs force kernels map pairs onto threads: the Layout of a run, chosen by size and
device (measured with ``decco-warp bench``, docs/benchmarks.md).  Plain data, no launches: the
engine and its force paths (forces.py) both read it."""

from __future__ import annotations

from dataclasses import dataclass

from .kernels.newton import NEWTON_TILE_MAX
from .errors import InputError


@dataclass(frozen=True)
class Layout:
    """How the tiled force kernel maps pairs onto threads.

    A block of ``block_dim`` threads (1 on CPU, where Warp runs one thread per
    block) owns ``particles_per_block`` particles i and sweeps the j in tiles of
    ``block_dim``; each j load serves all particles of the block.  Each thread
    notes up to ``contact_slots`` contact candidates per particle before falling
    back to a second look.
    """

    block_dim: int
    particles_per_block: int
    contact_slots: int = 4
    max_registers: int = 0
    """Cap on registers per thread on CUDA (0: the compiler's choice)."""
    newton: bool = False
    """Each pair once (Newton's third law, kernels/newton.py): a block is one
    warp (``block_dim`` 32 on a GPU, 1 on the CPU) meeting two tiles of ``particles_per_block``
    particles, gravity given to both sides, then the contacts in their own pass.
    ``contact_slots`` is unused."""
    fuse_kicks: bool = True
    """Steps share launches (:meth:`Engine.advance`): the last half kick of a step, the next one's
    first half kick and drift and the packing of the bodies for its sweep are one kernel; the same
    numbers, bit for bit, as the launches of :meth:`Engine.step` (False: those, for comparison)."""

    def __post_init__(self):
        for name in ("block_dim", "particles_per_block", "contact_slots"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < 1:
                raise InputError(f"Layout.{name} must be a positive integer; got {value!r}")
        if not isinstance(self.max_registers, int) or self.max_registers < 0:
            raise InputError(f"Layout.max_registers must be an integer >= 0; got {self.max_registers!r}")
        for name in ("newton", "fuse_kicks"):
            if not isinstance(getattr(self, name), bool):
                raise InputError(f"Layout.{name} must be true or false; got {getattr(self, name)!r}")
        if self.newton and (self.particles_per_block % self.block_dim or self.particles_per_block > NEWTON_TILE_MAX):
            raise InputError(
                "a Newton layout's particles_per_block must be a multiple of its block_dim (each lane keeps "
                f"as many particles) and at most {NEWTON_TILE_MAX}; got {self}"
            )


    def describe(self) -> str:
        """In words, for ``decco-warp bench`` and ``info``."""
        registers = f", <= {self.max_registers} registers" if self.max_registers else ""
        kicks = "" if self.fuse_kicks else ", kicks unfused"
        if self.newton:
            return f"each pair once: a warp of {self.block_dim} meets tiles of {self.particles_per_block}" + registers + kicks
        return f"{self.block_dim} threads x {self.particles_per_block} per block, {self.contact_slots} slots" + registers + kicks


#: Threads a block for the kernels of one thread a particle (the packing, the kicks and drifts, the
#: Newton sweep's gather, the neighbour list's build).  A thread's arithmetic is the same at any
#: block size, and so is the motion; Warp's default, 256, puts 6 250 particles in 25 blocks, on 25 of
#: a GPU's 132 SMs (docs/benchmarks.md, "The device limit").
PARTICLE_BLOCK = 256


def particle_block() -> int:
    """``block_dim`` of a launch of one thread a particle: :data:`PARTICLE_BLOCK`, read at launch."""
    return PARTICLE_BLOCK


#: Systems up to this many particles take the Newton layout on CUDA, which keeps a field sum and
#: a candidate word per particle and tile of 64 (N^2 / 64 x 20 bytes: 5.4 GB at 131 072 particles);
#: past it all-pairs takes the fused layout, which keeps nothing.
NEWTON_MAX = 131_072


def fused_layout(n: int, device: str) -> Layout:
    """The fused layout (one kernel: gravity of every ordered pair and the contacts) for ``n``
    particles on ``device``.

    CUDA (H100, docs/benchmarks.md): 128 threads per block, 4 particles per block sharing each j
    load; 64 threads below 4096 particles, for more blocks.  A thread meets a given particle's few
    contacts rarely, so 4 slots suffice.  Registers capped at 128: the rare float64 contact code
    spills a little and the sweep keeps its occupancy (+20 % at N = 65 536).
    CPU: the one thread of a block sees every contact of its particles, up to ~15 in a pile.
    """
    if device.startswith("cuda"):
        per_block = 128 if n >= 4096 else 64
        return Layout(block_dim=per_block, particles_per_block=4, contact_slots=4, max_registers=128)
    return Layout(block_dim=1, particles_per_block=4, contact_slots=16)


def choose_layout(n: int, device: str) -> Layout:
    """The force-kernel layout for ``n`` particles on ``device`` (measured with ``decco-warp bench --layouts``).

    CUDA (H100, docs/benchmarks.md): each pair once (Newton's third law), a warp meeting two tiles
    of 64 particles: 1.7x to 2.4x the fused layout's full step from 5 500 to 131 072 particles.  Past
    ``NEWTON_MAX`` particles, and on the CPU (where it gains only ~20 %), the :func:`fused_layout`.
    """
    if device.startswith("cuda") and n <= NEWTON_MAX:
        return newton_layout(device)
    return fused_layout(n, device)


#: ``[run] layout``: the force kernel's layout for a run.  "auto" is :func:`choose_layout`;
#: "newton" computes each pair once (the CUDA default up to NEWTON_MAX) on any device, where it
#: changes the order of float operations, so the motion differs from "auto" at round-off only.
LAYOUT_CHOICES = ("auto", "newton")


def newton_layout(device: str) -> Layout:
    """The Newton layout (each pair once, kernels/newton.py) on ``device``:
    a warp meeting tiles of 64 on CUDA, tiles of 4 on the CPU's one lane."""
    if device.startswith("cuda"):
        return Layout(block_dim=32, particles_per_block=NEWTON_TILE_MAX, newton=True)
    return Layout(block_dim=1, particles_per_block=4, newton=True)


#: Host bytes per tile pair while the Newton tables are built (gravity_solvers.newton_tiles: the index pairs
#: and six columns in int64, then the int32 table that goes to the device).
NEWTON_TABLE_BYTES = 2 * 8 + 6 * 8 + 6 * 4


def newton_scratch_bytes(n: int, layout: Layout, vector_bytes: int, listing: bool) -> int:
    """Bytes the Newton sweep keeps for a system of ``n`` particles (gravity_solvers.PairsOnce): for each
    of its (n / tile)^2 rows a field sum per particle of a tile (``vector_bytes``: 12 in mixed
    precision, 24 in double) and, where it lists contact candidates, a 64-bit word; the tile-pair
    table as it is built; each particle's gather entry.  O(N^2 / tile): the CPU's tiles of 4 make
    it the largest array of an all-pairs run there."""
    tiles = -(-n // layout.particles_per_block)
    rows = tiles * tiles * layout.particles_per_block * (vector_bytes + (8 if listing else 0))
    return rows + tiles * (tiles + 1) // 2 * NEWTON_TABLE_BYTES + 16 * n


def layout_for(choice: str, n: int, device: str) -> Layout | None:
    """The :class:`Layout` a run's ``layout`` choice names for ``n`` particles on ``device``
    (None for "auto": the engine's own choice)."""
    if choice not in LAYOUT_CHOICES:
        raise InputError(f"layout must be one of {', '.join(LAYOUT_CHOICES)}; got {choice!r}")
    return None if choice == "auto" else newton_layout(device)


def parse_layout(text: str, device: str) -> Layout:
    """A layout written BLOCK_DIM:PER_BLOCK[:SLOTS[:MAX_REGISTERS]] or
    BLOCK_DIM:TILE[:SLOTS[:MAX_REGISTERS]]:newton, either with :unfused (``decco-warp bench --layouts``);
    ValueError, naming the forms, for anything else or what ``device`` cannot run."""
    try:
        parts = text.split(":")
        flags = []
        while parts and parts[-1] in ("newton", "unfused") and parts[-1] not in flags:
            flags.append(parts.pop())
        values = [int(v) for v in parts]
        on_cuda = device.startswith("cuda")
        if len(values) not in (2, 3, 4) or (not on_cuda and values[0] != 1) or ("newton" in flags and on_cuda and values[0] != 32):
            raise InputError
        return Layout(*values, newton="newton" in flags, fuse_kicks="unfused" not in flags)
    except ValueError:
        raise InputError(
            "--layouts entries must be BLOCK_DIM:PER_BLOCK[:SLOTS[:MAX_REGISTERS]] or "
            "BLOCK_DIM:TILE[:SLOTS[:MAX_REGISTERS]]:newton (BLOCK_DIM 32, TILE a multiple of it; SLOTS unused), "
            f"either with :unfused (the kicks in launches of their own), BLOCK_DIM 1 on CPU; got {text!r}"
        ) from None

"""The tree path's device arrays and launches: gravity from a radix tree, contact candidates from a
hash grid (kernels/tree.py).  The engine owns one of these when ``Params.gravity == "tree"``."""

from __future__ import annotations

import warp as wp

from .kernels import tree as kernels
from .kernels.pair import TREE_GRID_MARGIN, host_reach

#: Hash grid cells per axis (the grid wraps: a bigger pile costs longer cell lists, not errors).
GRID_CELLS = 128
#: Threads per particle's walk on a GPU (kernels.walk_roots): the tree is split into this many
#: subtrees and each particle walks each one in its own thread.  A warp's 32 neighbouring particles
#: then mostly take the same few nodes of a part whole, and the GPU has work in flight: on the H100
#: the walk of an 80 000-particle pile is 1.73x faster at 64 parts than at 1, 1e6 particles 1.6x
#: (docs/benchmarks.md); more parts open more large nodes that one walk would take whole.
WALK_PARTS = 64
#: At most this many partial fields (12 bytes each in float32) are kept: 768 MB.
MAX_PARTIAL_FIELDS = 1 << 26


def walk_parts(count: int, device: str) -> int:
    """Threads per particle's walk: one on a CPU (its few threads are busy anyway, and each part
    costs opened nodes); WALK_PARTS on a GPU, fewer for the largest N."""
    if not str(device).startswith("cuda"):
        return 1
    return max(1, min(WALK_PARTS, MAX_PARTIAL_FIELDS // max(count, 1)))


class GravityTree:
    """Arrays for ``count`` particles on ``device``; rebuilt from the positions at every evaluation.
    ``parts``: threads per particle's walk (default :func:`walk_parts`)."""

    def __init__(self, count: int, device: str, precision: str = "mixed", parts: int | None = None):
        self.count, self.device = count, device
        self.precision = precision
        self.parts = walk_parts(count, device) if parts is None else parts
        self._gravity_kernel = kernels.tree_gravity(precision)
        nodes = max(2 * count - 1, 1)
        internal = max(count - 1, 1)

        def zeros(shape, dtype):
            return wp.zeros(shape, dtype=dtype, device=device)

        self.box = zeros(2, wp.vec3d)
        self.keys = zeros(2 * count, wp.int32)  # radix_sort_pairs needs room for 2 n
        self.order = zeros(2 * count, wp.int32)
        self.nodes = kernels.TreeNodes()
        self.nodes.child = zeros((internal, 2), wp.int32)
        self.nodes.parent = zeros(nodes, wp.int32)
        self.nodes.escape = zeros(nodes, wp.int32)
        self.nodes.first = zeros(internal, wp.int32)
        self.nodes.last = zeros(internal, wp.int32)
        self.nodes.mass = zeros(nodes, wp.float64)
        self.nodes.centre = zeros(nodes, wp.vec3d)
        self.nodes.quadrupole = zeros(nodes, wp.mat33d)
        self.nodes.low = zeros(nodes, wp.vec3d)
        self.nodes.high = zeros(nodes, wp.vec3d)
        self.nodes.size = zeros(nodes, wp.float64)
        self.nodes.offset = zeros(nodes, wp.float64)
        self.pending = zeros(1, wp.int32)  # 1 while the root's moments are unsummed: the levels' loop condition
        self.done = (zeros(nodes, wp.int32), zeros(nodes, wp.int32))
        # Walk records (kernels.walk_records): where each node is and what it links to, and its
        # moments for the gravity walk and for the float64 potential walk of frames.
        self.leaf_position = zeros(count, wp.vec3d)
        self.links = zeros(nodes, wp.vec4i)
        vec4 = {p: wp.vec4f if p == "mixed" else wp.vec4d for p in {precision, "float64"}}
        self.place = {p: zeros(nodes, v) for p, v in vec4.items()}
        self.moments = {p: zeros((nodes, 2), v) for p, v in vec4.items()}
        self.roots = zeros(self.parts, wp.int32)
        self.field_parts = zeros((self.parts, count), wp.vec3f if precision == "mixed" else wp.vec3d)
        self.potential_parts = zeros((self.parts, count), wp.float64)
        self.points = zeros(count, wp.vec3)
        self.grid = wp.HashGrid(GRID_CELLS, GRID_CELLS, GRID_CELLS, device=device)
        self.grid.reserve(count)

    def _walk_records(self, precision: str, G: float, theta_open: float) -> list:
        """The nodes' walk records for this G and theta_open (call :meth:`build` first)."""
        place, moments = self.place[precision], self.moments[precision]
        inputs = [wp.float64(G), wp.float64(1.0 / theta_open), self.count, self.nodes, self.box]
        self._launch(kernels.walk_records(precision), max(2 * self.count - 1, 1), inputs, [place, self.leaf_position, self.links, moments])
        self._launch(kernels.walk_roots, 1, [self.links], [self.roots])
        return [self.box, place, self.leaf_position, self.links, moments, self.roots]

    def _launch(self, kernel, dim: int, inputs: list, outputs: list) -> None:
        wp.launch(kernel, dim=dim, inputs=inputs, outputs=outputs, device=self.device)

    def build(self, position: wp.array, mass: wp.array) -> None:
        """Sort the particles along a Morton curve, link the tree and sum every node's moments."""
        n = self.count
        self._launch(kernels.reset_box, 1, [], [self.box])
        self._launch(kernels.bounds, n, [position], [self.box])
        self._launch(kernels.morton_codes, n, [position, self.box], [self.keys, self.order])
        wp.utils.radix_sort_pairs(self.keys, self.order, n)
        if n > 1:
            self._launch(kernels.build_nodes, n - 1, [n, self.keys], [self.nodes])
        self._launch(kernels.escape_links, 2 * n - 1, [], [self.nodes])
        self._launch(kernels.leaf_moments, n, [n, mass, position, self.order], [self.nodes, *self.done])
        if n > 1:
            # Level by level until the root is summed, the loop's condition kept on the device: no
            # read-back, so a step with the tree is captured in a CUDA graph like any other.
            self.pending.fill_(1)
            wp.capture_while(self.pending, self._two_levels)

    def _two_levels(self) -> None:
        before, after = self.done
        self._launch(kernels.node_moments, self.count - 1, [before], [self.nodes, after, self.pending])
        self._launch(kernels.node_moments, self.count - 1, [after], [self.nodes, before, self.pending])

    def gravity(self, G: float, theta_open: float, mass: wp.array, force_out: wp.array) -> None:
        """force_out = gravity on every particle (call :meth:`build` first)."""
        records = self._walk_records(self.precision, G, theta_open)
        self._launch(self._gravity_kernel, self.parts * self.count, [self.count, *records], [self.field_parts])
        self._launch(kernels.sum_field_parts, self.count, [mass, self.field_parts, self.order], [force_out])

    def potential(self, G: float, theta_open: float, mass: wp.array, potential_out: wp.array) -> None:
        """potential_out = half of each particle's gravitational energy (call :meth:`build` first)."""
        records = self._walk_records("float64", G, theta_open)
        self._launch(kernels.tree_potential, self.parts * self.count, [self.count, *records], [self.potential_parts])
        self._launch(kernels.sum_potential_parts, self.count, [mass, self.potential_parts, self.order], [potential_out])

    def contact_candidates(self, position, radius, max_radius: float, candidate_count, candidates) -> None:
        """Each particle's contact candidates (neighbours within R_i + R_j, plus a margin), from the hash grid."""
        self._launch(kernels.float32_points, self.count, [position, self.box], [self.points])
        self.grid.build(self.points, host_reach(max_radius, max_radius, 0.0, TREE_GRID_MARGIN))
        self._launch(
            kernels.grid_candidates,
            self.count,
            [radius, wp.float64(max_radius), self.grid.id, self.points],
            [candidate_count, candidates],
        )

"""Gravity from an octree-like binary radix tree, and contact candidates from a hash grid.

The tree (Karras 2012, "Maximizing parallelism in the construction of BVHs, octrees and k-d
trees") is built every evaluation, all on the device:

1. ``bounds``: the box of all centres (atomic min/max);
2. ``morton_codes``: 10 bits per axis, interleaved into a 30-bit key, sorted with the particle
   indices (``wp.utils.radix_sort_pairs``, stable);
3. ``build_nodes``: internal node i of n - 1 finds its range of sorted particles and its split by
   binary searches on the length of the keys' common prefix (ties broken by position in the sort);
   leaves are nodes n - 1 .. 2n - 2;
4. ``node_moments``: mass, centre of mass, traceless quadrupole and box of each internal node from
   its two children, one launch per level (a node is summed once both children were summed by an
   earlier launch), so that no thread reads what another writes in the same launch;
5. ``escape_links``: each node's escape, the node a depth-first walk goes to once it is done with
   this node's subtree (the right sibling of its nearest ancestor-or-self that is a left child);
6. ``walk_records``: what a visit of each node reads, packed into three records (centre and
   opening reach, links, G-folded moments), once theta_open and G are known;
7. ``tree_gravity``: each particle walks the tree from the root without a stack: a node is used
   whole (monopole + quadrupole) when its size is below ``theta_open`` times its distance and the
   particle is not one of its own, and the walk goes to its escape; else it is opened (the walk
   goes to its first child); leaves are summed directly.  On a GPU the walk is split
   (``walk_roots``): the tree's largest subtrees are split until there are ``parts`` of them, each
   particle walks each part in its own thread, and ``sum_field_parts`` adds the parts in order.
   ``tree_potential`` walks the same way for the potential energy of frames.

The tree is built in float64 and deterministically: the sort is stable, each node's sum has a fixed
order, and each particle's walk is sequential.  The gravity walk evaluates nodes and pairs in the
run's precision (``tree_gravity(precision)``: float32 terms by default), the potential walk of
frames in float64.  Contacts do not use the tree: ``grid_candidates`` lists each
particle's neighbours that may touch it (searched within R_i + R_max of a ``wp.HashGrid``,
noted within R_i + R_j), and the contact pass of
:mod:`.contacts` evaluates them with the same pair functions as the all-pairs path.
"""

import functools
from typing import Any

import warp as wp

from .contacts import note_candidate
from .pair import TREE_GRID_MARGIN, inverse_sqrt_exact, inverse_sqrt_fast, reach, within_reach

wp.set_module_options({"enable_backward": False})

@wp.struct
class TreeNodes:
    """The tree: internal nodes 0 .. n - 2 (links and ranges), all 2n - 1 nodes' moments and boxes."""

    child: wp.array2d(dtype=wp.int32)  # internal node -> its two nodes
    parent: wp.array(dtype=wp.int32)  # node -> its internal node (-1 for the root)
    escape: wp.array(dtype=wp.int32)  # node -> where a depth-first walk goes after its subtree (-1: done)
    first: wp.array(dtype=wp.int32)  # internal node -> first sorted position it holds
    last: wp.array(dtype=wp.int32)  # ... and last
    mass: wp.array(dtype=wp.float64)
    centre: wp.array(dtype=wp.vec3d)  # centre of mass
    quadrupole: wp.array(dtype=wp.mat33d)  # traceless, about the centre of mass
    low: wp.array(dtype=wp.vec3d)  # box of the centres it holds
    high: wp.array(dtype=wp.vec3d)
    size: wp.array(dtype=wp.float64)  # the box's longest side
    offset: wp.array(dtype=wp.float64)  # distance from the box's centre to the centre of mass


@wp.kernel
def reset_box(
    # Out:
    box_out: wp.array(dtype=wp.vec3d),  # [0] = +big, [1] = -big: what bounds narrows
):
    big = wp.float64(1.0e300)
    box_out[0] = wp.vec3d(big, big, big)
    box_out[1] = wp.vec3d(-big, -big, -big)


@wp.kernel
def bounds(
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    # Out:
    box_inout: wp.array(dtype=wp.vec3d),  # preset by reset_box
):
    """box_inout[0] = componentwise min, box_inout[1] = max of the centres (preset to +big, -big)."""
    i = wp.tid()
    wp.atomic_min(box_inout, 0, position_in[i])
    wp.atomic_max(box_inout, 1, position_in[i])


@wp.func
def spread_bits(v: int) -> int:
    """The 10 low bits of v, two zero bits after each (bit k moves to bit 3k)."""
    x = v & 1023
    x = (x | (x << 16)) & 50331903  # 0x030000FF
    x = (x | (x << 8)) & 50393103  # 0x0300F00F
    x = (x | (x << 4)) & 51130563  # 0x030C30C3
    x = (x | (x << 2)) & 153391689  # 0x09249249
    return x


@wp.kernel
def morton_codes(
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    box_in: wp.array(dtype=wp.vec3d),  # the centres' [min, max] (bounds)
    # Out:
    keys_out: wp.array(dtype=wp.int32),
    order_out: wp.array(dtype=wp.int32),
):
    """keys_out[i]: the 30-bit Morton code of centre i in the box; order_out[i] = i (sorted along with the keys)."""
    i = wp.tid()
    low = box_in[0]
    extent = box_in[1] - low
    size = wp.max(wp.max(extent[0], extent[1]), extent[2])
    scale = wp.float64(0.0)
    if size > wp.float64(0.0):
        scale = wp.float64(1023.999) / size  # one cube, so that cells stay cubes
    q = (position_in[i] - low) * scale
    code = (spread_bits(int(q[0])) << 2) | (spread_bits(int(q[1])) << 1) | spread_bits(int(q[2]))
    keys_out[i] = wp.int32(code)
    order_out[i] = wp.int32(i)


@wp.func
def highest_bit(x: int) -> int:
    """Index of the highest set bit of 0 < x < 2^31."""
    n = int(0)
    if x >= 65536:
        x = x >> 16
        n += 16
    if x >= 256:
        x = x >> 8
        n += 8
    if x >= 16:
        x = x >> 4
        n += 4
    if x >= 4:
        x = x >> 2
        n += 2
    if x >= 2:
        n += 1
    return n


@wp.func
def common_prefix(keys_in: wp.array(dtype=wp.int32), count: int, i: int, j: int) -> int:
    """delta(i, j) of Karras: bits shared by the keys of sorted positions i and j (30 key bits, then
    31 bits of the positions themselves when the keys are equal); -1 outside the array."""
    if j < 0 or j >= count:
        return -1
    a = int(keys_in[i])
    b = int(keys_in[j])
    if a != b:
        return 29 - highest_bit(a ^ b)
    return 30 + 30 - highest_bit(i ^ j)


@wp.kernel
def build_nodes(
    # Model:
    count: int,  # particles
    # In:
    keys_in: wp.array(dtype=wp.int32),  # sorted Morton codes
    # Out:
    nodes_out: TreeNodes,  # child, parent, first, last
):
    """Internal node i (of count - 1): its range [first, last] of sorted positions and its two
    children (node indices; leaves are count - 1 + position).  Node 0 is the root."""
    i = wp.tid()
    direction = int(1)
    if common_prefix(keys_in, count, i, i + 1) < common_prefix(keys_in, count, i, i - 1):
        direction = -1
    floor_prefix = common_prefix(keys_in, count, i, i - direction)
    reach = int(2)
    while common_prefix(keys_in, count, i, i + reach * direction) > floor_prefix:
        reach = reach * 2
    length = int(0)
    step = reach // 2
    while step >= 1:
        if common_prefix(keys_in, count, i, i + (length + step) * direction) > floor_prefix:
            length += step
        step = step // 2
    j = i + length * direction
    node_prefix = common_prefix(keys_in, count, i, j)
    split = int(0)
    step = length
    while step > 1:
        step = (step + 1) // 2
        if common_prefix(keys_in, count, i, i + (split + step) * direction) > node_prefix:
            split += step
    gamma = i + split * direction + wp.min(direction, 0)
    low = wp.min(i, j)
    high = wp.max(i, j)
    left = gamma
    if low == gamma:
        left = count - 1 + gamma
    right = gamma + 1
    if high == gamma + 1:
        right = count - 1 + gamma + 1
    nodes_out.child[i, 0] = wp.int32(left)
    nodes_out.child[i, 1] = wp.int32(right)
    nodes_out.parent[left] = wp.int32(i)
    nodes_out.parent[right] = wp.int32(i)
    if i == 0:
        nodes_out.parent[0] = wp.int32(-1)
    nodes_out.first[i] = wp.int32(low)
    nodes_out.last[i] = wp.int32(high)


@wp.kernel
def escape_links(
    # Out:
    nodes_inout: TreeNodes,  # reads parent and child, writes escape
):
    """Node k's escape: climb while k is its parent's second child; the escape is then the second
    child of that parent (-1 past the root).  With it the walk needs no stack (a stack of a few dozen
    nodes per thread lives in slow local memory on a GPU), and visits the nodes in the order a
    stack that pops the first child first would."""
    k = wp.tid()
    node = k
    escape = int(-1)
    while node > 0 and escape < 0:
        up = int(nodes_inout.parent[node])
        if int(nodes_inout.child[up, 0]) == node:
            escape = int(nodes_inout.child[up, 1])
        node = up
    nodes_inout.escape[k] = wp.int32(escape)


@wp.kernel
def leaf_moments(
    # Model:
    count: int,  # particles
    mass_in: wp.array(dtype=wp.float64),
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    order_in: wp.array(dtype=wp.int32),  # the particles in sorted order
    # Out:
    nodes_out: TreeNodes,  # the leaves' moments and boxes
    done_a_out: wp.array(dtype=wp.int32),
    done_b_out: wp.array(dtype=wp.int32),
):
    """Leaf count - 1 + k holds the particle at sorted position k, summed from the start; internal
    node k starts unsummed (in both flag arrays, which the levels use in turn)."""
    k = wp.tid()
    leaf = count - 1 + k
    x = position_in[order_in[k]]
    nodes_out.mass[leaf] = mass_in[order_in[k]]
    nodes_out.centre[leaf] = x
    nodes_out.quadrupole[leaf] = wp.mat33d()
    nodes_out.low[leaf] = x
    nodes_out.high[leaf] = x
    nodes_out.size[leaf] = wp.float64(0.0)
    nodes_out.offset[leaf] = wp.float64(0.0)
    done_a_out[leaf] = 1
    done_b_out[leaf] = 1
    if k < count - 1:
        done_a_out[k] = 0
        done_b_out[k] = 0


@wp.func
def shifted_quadrupole(quadrupole: wp.mat33d, mass: wp.float64, offset: wp.vec3d) -> wp.mat33d:
    """A traceless quadrupole about a point ``offset`` away from its centre of mass:
    Q + m (3 d d^T - |d|^2 I)."""
    d2 = wp.dot(offset, offset)
    return quadrupole + mass * (wp.float64(3.0) * wp.outer(offset, offset) - d2 * wp.identity(n=3, dtype=wp.float64))


@wp.kernel
def node_moments(
    # In:
    done_before_in: wp.array(dtype=wp.int32),  # per node: summed by an earlier launch
    # Out:
    nodes_inout: TreeNodes,  # reads the children's moments, writes the node's
    done_after_out: wp.array(dtype=wp.int32),
    pending_out: wp.array(dtype=wp.int32),  # [0] = 0 once the root is summed
):
    """One level: an internal node whose children were both summed before this launch sums them.
    Flags are read from ``done_before_in`` and written to ``done_after_out`` only, so no thread reads
    what another writes in the same launch.  pending_out[0] = 0 once the root (node 0) is summed: the
    device-side loop condition, so that no launch count is read back to the host."""
    i = wp.tid()
    if done_before_in[i] != 0:
        done_after_out[i] = 1
        if i == 0:
            pending_out[0] = 0
        return
    a = int(nodes_inout.child[i, 0])
    b = int(nodes_inout.child[i, 1])
    if done_before_in[a] == 0 or done_before_in[b] == 0:
        done_after_out[i] = 0
        return
    if i == 0:
        pending_out[0] = 0
    mass = nodes_inout.mass[a] + nodes_inout.mass[b]
    centre = (nodes_inout.mass[a] * nodes_inout.centre[a] + nodes_inout.mass[b] * nodes_inout.centre[b]) / mass
    nodes_inout.mass[i] = mass
    nodes_inout.centre[i] = centre
    nodes_inout.quadrupole[i] = shifted_quadrupole(nodes_inout.quadrupole[a], nodes_inout.mass[a], nodes_inout.centre[a] - centre) + shifted_quadrupole(
        nodes_inout.quadrupole[b], nodes_inout.mass[b], nodes_inout.centre[b] - centre
    )
    low = wp.min(nodes_inout.low[a], nodes_inout.low[b])
    high = wp.max(nodes_inout.high[a], nodes_inout.high[b])
    extent = high - low
    nodes_inout.low[i] = low
    nodes_inout.high[i] = high
    # What the walk's opening test needs, once per node rather than once per visit.
    nodes_inout.size[i] = wp.max(wp.max(extent[0], extent[1]), extent[2])
    nodes_inout.offset[i] = wp.length(centre - wp.float64(0.5) * (high + low))
    done_after_out[i] = 1


@wp.func
def multipole_field(unit: Any, inv_d: Any, g_mass: Any, g_quadrupole: Any):
    """Acceleration at distance 1/inv_d along ``unit`` from a node's centre, with G folded into its
    mass and traceless quadrupole: -GM r^/r^2 + (GQ r^ - 5/2 (r^.GQ r^) r^)/r^4.  Written in unit
    vectors, each factor stays within float32's range for piles of 1e24 g and more."""
    inv_d2 = inv_d * inv_d
    q_unit = g_quadrupole * unit
    return inv_d2 * (-g_mass * unit + inv_d2 * (q_unit - type(inv_d)(2.5) * wp.dot(unit, q_unit) * unit))


@wp.func
def multipole_potential(unit: Any, inv_d: Any, g_mass: Any, g_quadrupole: Any):
    """Potential (per unit mass) at the same point: -GM/r - (r^.GQ r^)/(2 r^3), whose gradient is
    :func:`multipole_field` (with the opposite sign)."""
    return -inv_d * (g_mass + type(inv_d)(0.5) * inv_d * inv_d * wp.dot(unit, g_quadrupole * unit))


def _real_types(precision: str):
    """(scalar, vec3, vec4, mat33) of a precision's node and pair arithmetic."""
    if precision == "mixed":
        return wp.float32, wp.vec3f, wp.vec4f, wp.mat33f
    return wp.float64, wp.vec3d, wp.vec4d, wp.mat33d


@functools.cache
def walk_records(precision: str):
    """The kernel that packs each node's walk record (launch with dim = 2n - 1): what a visit reads,
    in three loads of 16 to 32 bytes instead of ten scattered ones (a GPU walk waits on its loads).

    - ``place``: centre of mass, relative to the box's centre, and the opening reach, size /
      theta_open + offset, in the precision's arithmetic (a node is at least its size / theta_open
      away when it is used, so float32's ~1e-7 of the box in its separation is far below the
      tree's error);
    - ``leaf_position``: each leaf's particle in float64, in sorted order (a leaf may be a
      neighbour a few radii away: its separation is taken in float64, as all-pairs does);
    - ``links``: first and last sorted position held, first child (-1 for a leaf), escape;
    - ``moments``: G M and the six components of G Q, in the precision's arithmetic (a leaf's
      centre is its particle's position, its G Q zero)."""
    real, _, vec4, _ = _real_types(precision)

    @wp.kernel(module="unique", enable_backward=False)
    def walk_records_kernel(
        # Model:
        G: wp.float64,
        inv_theta: wp.float64,  # 1 / theta_open
        count: int,  # particles
        # In:
        nodes_in: TreeNodes,
        box_in: wp.array(dtype=wp.vec3d),
        # Out:
        place_out: wp.array(dtype=vec4),
        leaf_position_out: wp.array(dtype=wp.vec3d),
        links_out: wp.array(dtype=wp.vec4i),
        moments_out: wp.array2d(dtype=vec4),
    ):
        node = wp.tid()
        centre = nodes_in.centre[node]
        relative = centre - wp.float64(0.5) * (box_in[0] + box_in[1])
        place_out[node] = vec4(real(relative[0]), real(relative[1]), real(relative[2]), real(nodes_in.size[node] * inv_theta + nodes_in.offset[node]))
        if node >= count - 1:
            position = node - (count - 1)
            leaf_position_out[position] = centre
            links_out[node] = wp.vec4i(position, position, -1, int(nodes_in.escape[node]))
        else:
            links_out[node] = wp.vec4i(int(nodes_in.first[node]), int(nodes_in.last[node]), int(nodes_in.child[node, 0]), int(nodes_in.escape[node]))
        g_quadrupole = G * nodes_in.quadrupole[node]
        moments_out[node, 0] = vec4(real(G * nodes_in.mass[node]), real(g_quadrupole[0, 0]), real(g_quadrupole[1, 1]), real(g_quadrupole[2, 2]))
        moments_out[node, 1] = vec4(real(g_quadrupole[0, 1]), real(g_quadrupole[0, 2]), real(g_quadrupole[1, 2]), real(0.0))

    return walk_records_kernel


@functools.cache
def tree_walk_function(precision: str):
    """The walk in a precision's arithmetic: ``"mixed"`` takes a leaf's separation in float64, a
    node's in float32 relative to the box's centre (a node used whole is at least size / theta_open
    away), and evaluates both in float32 (one rsqrt instruction on a GPU).  Per particle it agrees
    with the float64 walk to ~1e-6 (1.7e-5 at most on a 20 000-particle pile, near its centre where
    gravity cancels), far below the tree's ~1e-3.  ``"float64"`` evaluates everything in float64."""
    real, vec, vec4, mat = _real_types(precision)
    inverse_sqrt = inverse_sqrt_fast if precision == "mixed" else inverse_sqrt_exact

    @wp.func
    def tree_walk(
        k: int,
        start: int,
        count: int,
        box_in: wp.array(dtype=wp.vec3d),
        place_in: wp.array(dtype=vec4),
        leaf_position_in: wp.array(dtype=wp.vec3d),
        links_in: wp.array(dtype=wp.vec4i),
        moments_in: wp.array2d(dtype=vec4),
    ):
        """Acceleration and potential (per unit mass) at the particle at sorted position k, from every
        other particle under node ``start`` (the root: all others; -1: none); a kernel that uses one
        of them lets the compiler drop the other."""
        x = leaf_position_in[k]
        x_relative = vec(x - wp.float64(0.5) * (box_in[0] + box_in[1]))
        field = vec()
        potential = real(0.0)
        node = start
        end = int(-1)  # where the walk leaves start's subtree
        if start >= 0:
            end = int(links_in[start][3])
        while node != end:
            link = links_in[node]
            if node >= count - 1:  # a leaf: one particle, summed directly (not the particle itself)
                r = vec(x - leaf_position_in[link[0]])
                d2 = wp.dot(r, r)
                if int(link[0]) != k and d2 > real(0.0):
                    inv_d = inverse_sqrt(d2)
                    g_mass = moments_in[node, 0][0]
                    field -= (g_mass * inv_d * inv_d) * (r * inv_d)
                    potential -= g_mass * inv_d
                node = int(link[3])
                continue
            at = place_in[node]
            r = x_relative - vec(at[0], at[1], at[2])
            d2 = wp.dot(r, r)
            # Used whole only beyond size / theta_open plus the offset of its centre of mass from
            # its box's centre (Barnes & Hut's guard against a lopsided node), never for its own members.
            reach = at[3]
            own = k >= int(link[0]) and k <= int(link[1])
            if not own and reach * reach < d2:
                inv_d = inverse_sqrt(d2)
                unit = r * inv_d
                a = moments_in[node, 0]
                b = moments_in[node, 1]
                g_quadrupole = mat(a[1], b[0], b[1], b[0], a[2], b[2], b[1], b[2], a[3])
                field += multipole_field(unit, inv_d, a[0], g_quadrupole)
                potential += multipole_potential(unit, inv_d, a[0], g_quadrupole)
                node = int(link[3])
            else:
                node = int(link[2])
        return field, potential

    return tree_walk


@functools.cache
def tree_gravity(precision: str = "mixed"):
    """Build the gravity kernel of the tree path in a precision's arithmetic (launch with dim =
    parts N; then :func:`sum_field_parts`)."""
    tree_walk = tree_walk_function(precision)
    _, vec, vec4, _ = _real_types(precision)

    @wp.kernel(module="unique", enable_backward=False)
    def tree_gravity_kernel(
        # Model:
        count: int,  # particles
        # In:
        box_in: wp.array(dtype=wp.vec3d),
        place_in: wp.array(dtype=vec4),  # the walk records (walk_records)
        leaf_position_in: wp.array(dtype=wp.vec3d),
        links_in: wp.array(dtype=wp.vec4i),
        moments_in: wp.array2d(dtype=vec4),
        roots_in: wp.array(dtype=wp.int32),  # the parts' subtrees (walk_roots)
        # Out:
        field_parts_out: wp.array2d(dtype=vec),
    ):
        """The field at each particle from one part of the tree: thread part N + k walks the subtree
        ``roots_in[part]`` for the particle at sorted position k."""
        part = wp.tid() // count
        k = wp.tid() - part * count
        field, potential = tree_walk(k, int(roots_in[part]), count, box_in, place_in, leaf_position_in, links_in, moments_in)
        field_parts_out[part, k] = field

    return tree_gravity_kernel


@wp.kernel
def sum_field_parts(
    # Model:
    mass_in: wp.array(dtype=wp.float64),
    # In:
    field_parts_in: wp.array2d(dtype=Any),  # [part, sorted position] (tree_gravity)
    order_in: wp.array(dtype=wp.int32),  # the particles in sorted order
    # Out:
    force_out: wp.array(dtype=wp.vec3d),
):
    """force_out = mass times the field summed over the parts, in part order (deterministic)."""
    k = wp.tid()
    field = wp.vec3d()
    for part in range(field_parts_in.shape[0]):
        field += wp.vec3d(field_parts_in[part, k])
    i = int(order_in[k])
    force_out[i] = mass_in[i] * field


_walk_float64 = tree_walk_function("float64")


@wp.kernel
def tree_potential(
    # Model:
    count: int,  # particles
    # In:
    box_in: wp.array(dtype=wp.vec3d),
    place_in: wp.array(dtype=wp.vec4d),  # the float64 walk records (walk_records)
    leaf_position_in: wp.array(dtype=wp.vec3d),
    links_in: wp.array(dtype=wp.vec4i),
    moments_in: wp.array2d(dtype=wp.vec4d),
    roots_in: wp.array(dtype=wp.int32),  # the parts' subtrees (walk_roots)
    # Out:
    potential_parts_out: wp.array2d(dtype=wp.float64),
):
    """The potential (per unit mass) at each particle from one part of the tree, for frames on the
    tree path: always float64 (float64 records), so that the energy ledger closes to round-off."""
    part = wp.tid() // count
    k = wp.tid() - part * count
    field, potential = _walk_float64(k, int(roots_in[part]), count, box_in, place_in, leaf_position_in, links_in, moments_in)
    potential_parts_out[part, k] = potential


@wp.kernel
def sum_potential_parts(
    # Model:
    mass_in: wp.array(dtype=wp.float64),
    # In:
    potential_parts_in: wp.array2d(dtype=wp.float64),  # [part, sorted position] (tree_potential)
    order_in: wp.array(dtype=wp.int32),  # the particles in sorted order
    # Out:
    potential_out: wp.array(dtype=wp.float64),
):
    """Half of each particle's gravitational energy with all others (summed over particles, the
    potential energy): the parts summed in order."""
    k = wp.tid()
    potential = wp.float64(0.0)
    for part in range(potential_parts_in.shape[0]):
        potential += potential_parts_in[part, k]
    i = int(order_in[k])
    potential_out[i] = wp.float64(0.5) * mass_in[i] * potential


@wp.kernel
def walk_roots(
    # In:
    links_in: wp.array(dtype=wp.vec4i),  # the nodes' links (walk_records)
    # Out:
    roots_out: wp.array(dtype=wp.int32),  # the parts' subtrees, in depth-first order (-1: an empty part)
):
    """Split the tree into len(roots_out) subtrees that hold every leaf, so that as many threads walk
    for each particle (a GPU needs ~1e6 threads in flight to hide the walk's memory latency; one
    per particle is too few below a few 1e5): from the root, split the subtree holding most
    particles into its two children, in place (the parts stay in depth-first order), until there
    are enough.  Parts left over (fewer particles than parts) are -1, an empty walk.  One thread."""
    parts = roots_out.shape[0]
    roots_out[0] = wp.int32(0)
    for s in range(1, parts):
        roots_out[s] = wp.int32(-1)
    made = int(1)
    while made < parts:
        best = int(-1)
        most = int(1)
        for s in range(made):
            link = links_in[roots_out[s]]
            held = int(link[1]) - int(link[0]) + 1
            if held > most:
                best = s
                most = held
        if best < 0:  # every part is a leaf
            made = parts
        else:
            s = made
            while s > best + 1:
                roots_out[s] = roots_out[s - 1]
                s -= 1
            first_child = int(links_in[roots_out[best]][2])
            roots_out[best] = wp.int32(first_child)
            roots_out[best + 1] = links_in[first_child][3]  # the second child: where the first's walk goes next
            made += 1


@wp.kernel
def grid_candidates(
    # Model:
    radius_in: wp.array(dtype=wp.float64),
    max_radius: wp.float64,
    # In:
    grid: wp.uint64,  # the hash grid of the points
    points_in: wp.array(dtype=wp.vec3),  # the centres in float32 (float32_points)
    # Out:
    candidate_count_out: wp.array(dtype=wp.int32),  # candidates met (past the list's width: an overflow)
    candidates_out: wp.array2d(dtype=wp.int32),  # the first of them, in increasing j
):
    """Each particle's contact candidates: neighbours closer than (R_i + R_j) TREE_GRID_MARGIN, a
    superset of its contacts confirmed in float64 by the contact pass.  The grid is asked for
    R_i + R_max and returns whole cells (90 points on average in the shipped pile, up to 260);
    only the few that can touch are noted, so that the list does not overflow."""
    i = wp.tid()
    margin, none = wp.float64(TREE_GRID_MARGIN), wp.float64(0.0)
    query = wp.hash_grid_query(grid, points_in[i], wp.float32(reach(radius_in[i], max_radius, none, margin)))
    j = int(0)
    noted = int(0)
    while wp.hash_grid_query_next(query, j):
        if j != i:
            touch = wp.float32(reach(radius_in[i], radius_in[j], none, margin))
            if within_reach(wp.length_sq(points_in[j] - points_in[i]), touch, wp.float32(1.0)):
                noted = note_candidate(candidates_out, i, noted, j)
    candidate_count_out[i] = wp.int32(noted)


@wp.kernel
def float32_points(
    # In:
    position_in: wp.array(dtype=wp.vec3d),
    origin_in: wp.array(dtype=wp.vec3d),  # [0]: the box's low corner (bounds)
    # Out:
    points_out: wp.array(dtype=wp.vec3),
):
    """Centres relative to the box corner, in float32, for the hash grid."""
    i = wp.tid()
    points_out[i] = wp.vec3(position_in[i] - origin_in[0])

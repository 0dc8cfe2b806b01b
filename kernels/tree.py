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
from .pair import inverse_sqrt_exact, inverse_sqrt_fast

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
def reset_box(box: wp.array(dtype=wp.vec3d)):
    big = wp.float64(1.0e300)
    box[0] = wp.vec3d(big, big, big)
    box[1] = wp.vec3d(-big, -big, -big)


@wp.kernel
def bounds(position_in: wp.array(dtype=wp.vec3d), box: wp.array(dtype=wp.vec3d)):
    """box[0] = componentwise min, box[1] = max of the centres (box preset to +inf, -inf)."""
    i = wp.tid()
    wp.atomic_min(box, 0, position_in[i])
    wp.atomic_max(box, 1, position_in[i])


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
    position_in: wp.array(dtype=wp.vec3d),
    box: wp.array(dtype=wp.vec3d),
    keys: wp.array(dtype=wp.int32),
    order: wp.array(dtype=wp.int32),
):
    """keys[i]: the 30-bit Morton code of centre i in the box; order[i] = i (sorted along with keys)."""
    i = wp.tid()
    low = box[0]
    extent = box[1] - low
    size = wp.max(wp.max(extent[0], extent[1]), extent[2])
    scale = wp.float64(0.0)
    if size > wp.float64(0.0):
        scale = wp.float64(1023.999) / size  # one cube, so that cells stay cubes
    q = (position_in[i] - low) * scale
    code = (spread_bits(int(q[0])) << 2) | (spread_bits(int(q[1])) << 1) | spread_bits(int(q[2]))
    keys[i] = wp.int32(code)
    order[i] = wp.int32(i)


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
def common_prefix(keys: wp.array(dtype=wp.int32), count: int, i: int, j: int) -> int:
    """delta(i, j) of Karras: bits shared by the keys of sorted positions i and j (30 key bits, then
    31 bits of the positions themselves when the keys are equal); -1 outside the array."""
    if j < 0 or j >= count:
        return -1
    a = int(keys[i])
    b = int(keys[j])
    if a != b:
        return 29 - highest_bit(a ^ b)
    return 30 + 30 - highest_bit(i ^ j)


@wp.kernel
def build_nodes(keys: wp.array(dtype=wp.int32), count: int, nodes: TreeNodes):
    """Internal node i (of count - 1): its range [first, last] of sorted positions and its two
    children (node indices; leaves are count - 1 + position).  Node 0 is the root."""
    i = wp.tid()
    direction = int(1)
    if common_prefix(keys, count, i, i + 1) < common_prefix(keys, count, i, i - 1):
        direction = -1
    floor_prefix = common_prefix(keys, count, i, i - direction)
    reach = int(2)
    while common_prefix(keys, count, i, i + reach * direction) > floor_prefix:
        reach = reach * 2
    length = int(0)
    step = reach // 2
    while step >= 1:
        if common_prefix(keys, count, i, i + (length + step) * direction) > floor_prefix:
            length += step
        step = step // 2
    j = i + length * direction
    node_prefix = common_prefix(keys, count, i, j)
    split = int(0)
    step = length
    while step > 1:
        step = (step + 1) // 2
        if common_prefix(keys, count, i, i + (split + step) * direction) > node_prefix:
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
    nodes.child[i, 0] = wp.int32(left)
    nodes.child[i, 1] = wp.int32(right)
    nodes.parent[left] = wp.int32(i)
    nodes.parent[right] = wp.int32(i)
    if i == 0:
        nodes.parent[0] = wp.int32(-1)
    nodes.first[i] = wp.int32(low)
    nodes.last[i] = wp.int32(high)


@wp.kernel
def escape_links(nodes: TreeNodes):
    """Node k's escape: climb while k is its parent's second child; the escape is then the second
    child of that parent (-1 past the root).  With it the walk needs no stack (a stack of a few dozen
    nodes per thread lives in slow local memory on a GPU), and visits the nodes in the order a
    stack that pops the first child first would."""
    k = wp.tid()
    node = k
    escape = int(-1)
    while node > 0 and escape < 0:
        up = int(nodes.parent[node])
        if int(nodes.child[up, 0]) == node:
            escape = int(nodes.child[up, 1])
        node = up
    nodes.escape[k] = wp.int32(escape)


@wp.kernel
def leaf_moments(
    position_in: wp.array(dtype=wp.vec3d),
    mass_in: wp.array(dtype=wp.float64),
    order: wp.array(dtype=wp.int32),
    count: int,
    nodes: TreeNodes,
    done_a: wp.array(dtype=wp.int32),
    done_b: wp.array(dtype=wp.int32),
):
    """Leaf count - 1 + k holds the particle at sorted position k, summed from the start; internal
    node k starts unsummed (in both flag arrays, which the levels use in turn)."""
    k = wp.tid()
    leaf = count - 1 + k
    x = position_in[order[k]]
    nodes.mass[leaf] = mass_in[order[k]]
    nodes.centre[leaf] = x
    nodes.quadrupole[leaf] = wp.mat33d()
    nodes.low[leaf] = x
    nodes.high[leaf] = x
    nodes.size[leaf] = wp.float64(0.0)
    nodes.offset[leaf] = wp.float64(0.0)
    done_a[leaf] = 1
    done_b[leaf] = 1
    if k < count - 1:
        done_a[k] = 0
        done_b[k] = 0


@wp.func
def shifted_quadrupole(quadrupole: wp.mat33d, mass: wp.float64, offset: wp.vec3d) -> wp.mat33d:
    """A traceless quadrupole about a point ``offset`` away from its centre of mass:
    Q + m (3 d d^T - |d|^2 I)."""
    d2 = wp.dot(offset, offset)
    return quadrupole + mass * (wp.float64(3.0) * wp.outer(offset, offset) - d2 * wp.identity(n=3, dtype=wp.float64))


@wp.kernel
def node_moments(
    nodes: TreeNodes,
    done_before: wp.array(dtype=wp.int32),
    done_after: wp.array(dtype=wp.int32),
    pending: wp.array(dtype=wp.int32),
):
    """One level: an internal node whose children were both summed before this launch sums them.
    Flags are read from ``done_before`` and written to ``done_after`` only, so no thread reads
    what another writes in the same launch.  pending[0] = 0 once the root (node 0) is summed: the
    device-side loop condition, so that no launch count is read back to the host."""
    i = wp.tid()
    if done_before[i] != 0:
        done_after[i] = 1
        if i == 0:
            pending[0] = 0
        return
    a = int(nodes.child[i, 0])
    b = int(nodes.child[i, 1])
    if done_before[a] == 0 or done_before[b] == 0:
        done_after[i] = 0
        return
    if i == 0:
        pending[0] = 0
    mass = nodes.mass[a] + nodes.mass[b]
    centre = (nodes.mass[a] * nodes.centre[a] + nodes.mass[b] * nodes.centre[b]) / mass
    nodes.mass[i] = mass
    nodes.centre[i] = centre
    nodes.quadrupole[i] = shifted_quadrupole(nodes.quadrupole[a], nodes.mass[a], nodes.centre[a] - centre) + shifted_quadrupole(
        nodes.quadrupole[b], nodes.mass[b], nodes.centre[b] - centre
    )
    low = wp.min(nodes.low[a], nodes.low[b])
    high = wp.max(nodes.high[a], nodes.high[b])
    extent = high - low
    nodes.low[i] = low
    nodes.high[i] = high
    # What the walk's opening test needs, once per node rather than once per visit.
    nodes.size[i] = wp.max(wp.max(extent[0], extent[1]), extent[2])
    nodes.offset[i] = wp.length(centre - wp.float64(0.5) * (high + low))
    done_after[i] = 1


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
        G: wp.float64,
        inv_theta: wp.float64,
        count: int,
        nodes: TreeNodes,
        box: wp.array(dtype=wp.vec3d),
        place: wp.array(dtype=vec4),
        leaf_position: wp.array(dtype=wp.vec3d),
        links: wp.array(dtype=wp.vec4i),
        moments: wp.array2d(dtype=vec4),
    ):
        node = wp.tid()
        centre = nodes.centre[node]
        relative = centre - wp.float64(0.5) * (box[0] + box[1])
        place[node] = vec4(real(relative[0]), real(relative[1]), real(relative[2]), real(nodes.size[node] * inv_theta + nodes.offset[node]))
        if node >= count - 1:
            position = node - (count - 1)
            leaf_position[position] = centre
            links[node] = wp.vec4i(position, position, -1, int(nodes.escape[node]))
        else:
            links[node] = wp.vec4i(int(nodes.first[node]), int(nodes.last[node]), int(nodes.child[node, 0]), int(nodes.escape[node]))
        g_quadrupole = G * nodes.quadrupole[node]
        moments[node, 0] = vec4(real(G * nodes.mass[node]), real(g_quadrupole[0, 0]), real(g_quadrupole[1, 1]), real(g_quadrupole[2, 2]))
        moments[node, 1] = vec4(real(g_quadrupole[0, 1]), real(g_quadrupole[0, 2]), real(g_quadrupole[1, 2]), real(0.0))

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
        box: wp.array(dtype=wp.vec3d),
        place: wp.array(dtype=vec4),
        leaf_position: wp.array(dtype=wp.vec3d),
        links: wp.array(dtype=wp.vec4i),
        moments: wp.array2d(dtype=vec4),
    ):
        """Acceleration and potential (per unit mass) at the particle at sorted position k, from every
        other particle under node ``start`` (the root: all others; -1: none); a kernel that uses one
        of them lets the compiler drop the other."""
        x = leaf_position[k]
        x_relative = vec(x - wp.float64(0.5) * (box[0] + box[1]))
        field = vec()
        potential = real(0.0)
        node = start
        end = int(-1)  # where the walk leaves start's subtree
        if start >= 0:
            end = int(links[start][3])
        while node != end:
            link = links[node]
            if node >= count - 1:  # a leaf: one particle, summed directly (not the particle itself)
                r = vec(x - leaf_position[link[0]])
                d2 = wp.dot(r, r)
                if int(link[0]) != k and d2 > real(0.0):
                    inv_d = inverse_sqrt(d2)
                    g_mass = moments[node, 0][0]
                    field -= (g_mass * inv_d * inv_d) * (r * inv_d)
                    potential -= g_mass * inv_d
                node = int(link[3])
                continue
            at = place[node]
            r = x_relative - vec(at[0], at[1], at[2])
            d2 = wp.dot(r, r)
            # Used whole only beyond size / theta_open plus the offset of its centre of mass from
            # its box's centre (Barnes & Hut's guard against a lopsided node), never for its own members.
            reach = at[3]
            own = k >= int(link[0]) and k <= int(link[1])
            if not own and reach * reach < d2:
                inv_d = inverse_sqrt(d2)
                unit = r * inv_d
                a = moments[node, 0]
                b = moments[node, 1]
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
        count: int,
        box: wp.array(dtype=wp.vec3d),
        place: wp.array(dtype=vec4),
        leaf_position: wp.array(dtype=wp.vec3d),
        links: wp.array(dtype=wp.vec4i),
        moments: wp.array2d(dtype=vec4),
        roots: wp.array(dtype=wp.int32),
        field_parts: wp.array2d(dtype=vec),
    ):
        """The field at each particle from one part of the tree: thread part N + k walks the subtree
        ``roots[part]`` for the particle at sorted position k."""
        part = wp.tid() // count
        k = wp.tid() - part * count
        field, potential = tree_walk(k, int(roots[part]), count, box, place, leaf_position, links, moments)
        field_parts[part, k] = field

    return tree_gravity_kernel


@wp.kernel
def sum_field_parts(
    field_parts: wp.array2d(dtype=Any), order: wp.array(dtype=wp.int32), mass_in: wp.array(dtype=wp.float64), force_out: wp.array(dtype=wp.vec3d)
):
    """force_out = mass times the field summed over the parts, in part order (deterministic)."""
    k = wp.tid()
    field = wp.vec3d()
    for part in range(field_parts.shape[0]):
        field += wp.vec3d(field_parts[part, k])
    i = int(order[k])
    force_out[i] = mass_in[i] * field


_walk_float64 = tree_walk_function("float64")


@wp.kernel
def tree_potential(
    count: int,
    box: wp.array(dtype=wp.vec3d),
    place: wp.array(dtype=wp.vec4d),
    leaf_position: wp.array(dtype=wp.vec3d),
    links: wp.array(dtype=wp.vec4i),
    moments: wp.array2d(dtype=wp.vec4d),
    roots: wp.array(dtype=wp.int32),
    potential_parts: wp.array2d(dtype=wp.float64),
):
    """The potential (per unit mass) at each particle from one part of the tree, for frames on the
    tree path: always float64 (float64 records), so that the energy ledger closes to round-off."""
    part = wp.tid() // count
    k = wp.tid() - part * count
    field, potential = _walk_float64(k, int(roots[part]), count, box, place, leaf_position, links, moments)
    potential_parts[part, k] = potential


@wp.kernel
def sum_potential_parts(
    potential_parts: wp.array2d(dtype=wp.float64), order: wp.array(dtype=wp.int32), mass_in: wp.array(dtype=wp.float64), potential_out: wp.array(dtype=wp.float64)
):
    """Half of each particle's gravitational energy with all others (summed over particles, the
    potential energy): the parts summed in order."""
    k = wp.tid()
    potential = wp.float64(0.0)
    for part in range(potential_parts.shape[0]):
        potential += potential_parts[part, k]
    i = int(order[k])
    potential_out[i] = wp.float64(0.5) * mass_in[i] * potential


@wp.kernel
def walk_roots(links: wp.array(dtype=wp.vec4i), roots: wp.array(dtype=wp.int32)):
    """Split the tree into len(roots) subtrees that hold every leaf, so that as many threads walk
    for each particle (a GPU needs ~1e6 threads in flight to hide the walk's memory latency; one
    per particle is too few below a few 1e5): from the root, split the subtree holding most
    particles into its two children, in place (the parts stay in depth-first order), until there
    are enough.  Parts left over (fewer particles than parts) are -1, an empty walk.  One thread."""
    parts = roots.shape[0]
    roots[0] = wp.int32(0)
    for s in range(1, parts):
        roots[s] = wp.int32(-1)
    made = int(1)
    while made < parts:
        best = int(-1)
        most = int(1)
        for s in range(made):
            link = links[roots[s]]
            held = int(link[1]) - int(link[0]) + 1
            if held > most:
                best = s
                most = held
        if best < 0:  # every part is a leaf
            made = parts
        else:
            s = made
            while s > best + 1:
                roots[s] = roots[s - 1]
                s -= 1
            first_child = int(links[roots[best]][2])
            roots[best] = wp.int32(first_child)
            roots[best + 1] = links[first_child][3]  # the second child: where the first's walk goes next
            made += 1


@wp.kernel
def grid_candidates(
    grid: wp.uint64,
    points: wp.array(dtype=wp.vec3),
    radius_in: wp.array(dtype=wp.float64),
    max_radius: wp.float64,
    candidate_count: wp.array(dtype=wp.int32),
    candidates: wp.array2d(dtype=wp.int32),
):
    """Each particle's contact candidates: neighbours closer than (R_i + R_j) (1 + 1e-4), a
    superset of its contacts confirmed in float64 by the contact pass.  The grid is asked for
    R_i + R_max and returns whole cells (90 points on average in the shipped pile, up to 260);
    only the few that can touch are noted, so that the list does not overflow.  The margin covers
    float32 positions to |x| ~ 1e9 cm."""
    i = wp.tid()
    margin = wp.float64(1.0001)
    reach = wp.float32((radius_in[i] + max_radius) * margin)
    query = wp.hash_grid_query(grid, points[i], reach)
    j = int(0)
    noted = int(0)
    while wp.hash_grid_query_next(query, j):
        if j != i:
            touch = wp.float32((radius_in[i] + radius_in[j]) * margin)
            if wp.length_sq(points[j] - points[i]) < touch * touch:
                noted = note_candidate(candidates, i, noted, j)
    candidate_count[i] = wp.int32(noted)


@wp.kernel
def float32_points(position_in: wp.array(dtype=wp.vec3d), origin: wp.array(dtype=wp.vec3d), points: wp.array(dtype=wp.vec3)):
    """Centres relative to the box corner, in float32, for the hash grid."""
    i = wp.tid()
    points[i] = wp.vec3(position_in[i] - origin[0])

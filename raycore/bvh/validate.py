"""Checks that a BVH read from outside (a file, another process) is safe to traverse.

The traversal trusts its trees: it follows references without bounds checks and keeps a stack
of fixed size (``traverse.STACK_SIZE``, enough for ``MAX_DEPTH`` levels).  A tree that did not
come from this process's build must be checked before a kernel reads it, or a bad reference
would read out of bounds or overflow the stack (a crash, or a wrong answer).
"""

import numpy as np
from numba import njit

from raycore.bvh.build import MAX_DEPTH
from raycore.bvh.layout import COUNTS, NODE_WIDTH, REFS, WIDTH


def check_tree(nodes, leaf_limit, blocks, name):
    """Raise ``ValueError`` unless ``nodes`` is a wide BVH that the traversal can follow safely.

    Parameters
    ----------
    nodes : ndarray of float32, shape (K, NODE_WIDTH)
        Wide rows (:mod:`raycore.bvh.layout`), row 0 the root.
    leaf_limit : int
        Leaves reference items ``ref .. ref + ceil(count / blocks) - 1``, all below this.
    blocks : int
        Primitives per item a leaf references: 1 for a top-level tree's objects, a block's
        lanes for a mesh's blocks of triangles (:func:`raycore.bvh.simd.lanes_for`).
    name : str
        What the tree is, for the message.

    Notes
    -----
    Every internal child must be a later row, each row but the root the child of exactly one,
    and the tree at most ``MAX_DEPTH`` rows deep; unused slots must be as the build leaves them
    (empty box, no reference), since a reference of 0 there would be the root again.
    """
    if nodes.dtype != np.float32 or nodes.ndim != 2 or nodes.shape[1] != NODE_WIDTH or \
            len(nodes) == 0 or not nodes.flags.c_contiguous:
        raise ValueError(f"{name}: nodes must be a non-empty (K, {NODE_WIDTH}) float32 array")
    problem = _tree_problem(nodes, nodes.view(np.int32), leaf_limit, blocks)
    if problem:
        raise ValueError(f"{name}: {_PROBLEMS[problem].format(limit=leaf_limit)}")


_PROBLEMS = {
    1: "a node has a negative count",
    2: "a leaf references items outside [0, {limit})",
    3: "a node references a row that is not a later one",
    4: "its rows do not form one tree",
    5: f"deeper than {MAX_DEPTH} levels",
}


@njit(cache=True)
def _tree_problem(nodes, refs, leaf_limit, blocks):
    """0, or the key in _PROBLEMS of the first problem found (one pass over the rows: a child
    is a later row, so its parent's depth is known when it is reached)."""
    depth = np.full(len(nodes), -1, np.int64)
    depth[0] = 0
    for row in range(len(nodes)):
        if depth[row] < 0:  # no parent reached it
            return 4
        if depth[row] >= MAX_DEPTH:
            return 5
        for slot in range(WIDTH):
            count = np.int64(refs[row, COUNTS + slot])
            ref = np.int64(refs[row, REFS + slot])
            if count < 0:
                return 1
            if count > 0:
                # its ceil(count / blocks) items from ref fit below leaf_limit (a division per
                # leaf took a sixth of the check)
                if ref < 0 or count > (leaf_limit - ref) * blocks:
                    return 2
                continue
            unused = ref == 0
            for axis in range(3):
                unused &= nodes[row, axis * WIDTH + slot] == np.inf
                unused &= nodes[row, (axis + 3) * WIDTH + slot] == -np.inf
            if unused:
                continue
            if ref <= row or ref >= len(nodes):
                return 3
            if depth[ref] >= 0:  # a second parent
                return 4
            depth[ref] = depth[row] + 1
    return 0

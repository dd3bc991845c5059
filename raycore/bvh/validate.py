"""Checks that a BVH read from outside (a file, another process) is safe to traverse.

The traversal trusts its trees: it follows references without bounds checks and keeps a stack
of fixed size (``traverse.STACK_SIZE``, enough for ``MAX_DEPTH`` levels).  A tree that did not
come from this process's build must be checked before a kernel reads it, or a bad reference
would read out of bounds or overflow the stack (a crash, or a wrong answer).
"""

import numpy as np

from raycore.bvh.build import MAX_DEPTH
from raycore.bvh.layout import COUNTS, NODE_WIDTH, REFS, WIDTH


def check_tree(nodes, leaf_limit, per_leaf, name):
    """Raise ``ValueError`` unless ``nodes`` is a wide BVH that the traversal can follow safely.

    Parameters
    ----------
    nodes : ndarray of float32, shape (K, NODE_WIDTH)
        Wide rows (:mod:`raycore.bvh.layout`), row 0 the root.
    leaf_limit : int
        Leaves reference items ``ref .. ref + per_leaf(count) - 1``, all below this.
    per_leaf : callable
        Items a leaf of ``count`` (an int64 array) occupies: ``count`` objects of a top-level
        tree, ``ceil(count / 4)`` blocks of a mesh's.
    name : str
        What the tree is, for the message.

    Notes
    -----
    Every internal child must be a later row, each row but the root the child of exactly one,
    and the tree at most ``MAX_DEPTH`` rows deep; unused slots must be as the build leaves them
    (empty box, no reference), since a reference of 0 there would be the root again.
    """
    if nodes.dtype != np.float32 or nodes.ndim != 2 or nodes.shape[1] != NODE_WIDTH or \
            len(nodes) == 0:
        raise ValueError(f"{name}: nodes must be a non-empty (K, {NODE_WIDTH}) float32 array")
    refs = nodes.view(np.int32)
    counts = refs[:, COUNTS:COUNTS + WIDTH].astype(np.int64)
    firsts = refs[:, REFS:REFS + WIDTH].astype(np.int64)
    boxes = nodes[:, :6 * WIDTH].reshape(len(nodes), 6, WIDTH)
    unused = np.all(boxes[:, :3] == np.inf, axis=1) & np.all(boxes[:, 3:] == -np.inf, axis=1) \
        & (counts == 0) & (firsts == 0)
    if np.any(counts < 0):
        raise ValueError(f"{name}: a node has a negative count")
    leaf = counts > 0
    if np.any(leaf):
        last = firsts[leaf] + per_leaf(counts[leaf])
        if firsts[leaf].min() < 0 or last.max() > leaf_limit:
            raise ValueError(f"{name}: a leaf references items outside [0, {leaf_limit})")
    internal = ~leaf & ~unused
    parent = np.broadcast_to(np.arange(len(nodes))[:, None], internal.shape)[internal]
    child = firsts[internal]
    if np.any(child <= parent) or np.any(child >= len(nodes)):
        raise ValueError(f"{name}: a node references a row that is not a later one")
    if not np.array_equal(np.bincount(child, minlength=len(nodes)),
                          np.r_[0, np.ones(len(nodes) - 1, np.int64)]):
        raise ValueError(f"{name}: its rows do not form one tree")
    # each pass settles one more level (after pass k, a row deeper than k reads k), so MAX_DEPTH
    # passes tell whether some row is MAX_DEPTH deep: the stack holds (WIDTH - 1) per level
    depth = np.zeros(len(nodes), np.int64)
    for _ in range(MAX_DEPTH):
        updated = depth.copy()
        updated[child] = depth[parent] + 1
        if np.array_equal(updated, depth):
            break
        depth = updated
    if depth.max() >= MAX_DEPTH:
        raise ValueError(f"{name}: deeper than {MAX_DEPTH} levels")

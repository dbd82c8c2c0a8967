"""Body proportions for drawing a skeleton as capsules (pure numpy, no GL).

Every joint gets a radius; a bone is the rounded cone between its two joint spheres, so bones
meeting at a joint blend without gaps. Radii are fractions of the character's height: handed in per
joint when the caller knows what the joints are (``body_radii``: the studio sizes them from the joint
names with ``lmm.skeleton.body_radii``; NaN for a joint it does not know), otherwise from the joint's
place in the tree (joints far from the tips of the limbs and carrying many of them are thicker), so
any skeleton gets a plausible body.
Leaf joints (the loaders drop BVH end sites) get an extension so hands, toes and the head do not
end at the wrist, the ball of the foot or the base of the skull.
"""
from __future__ import annotations

import re

import numpy as np

# leaf joints: extension along the parent -> leaf direction, as (length / height, end radius / leaf radius)
NAME_LEAF_EXTENSIONS = (
    (r"finger|thumb|index|middle|ring|pinky|little", 0.012, 0.8),
    (r"toe|ball", 0.030, 0.85),
    (r"hand|wrist", 0.075, 0.8),
    (r"head|skull", 0.0, 1.0),    # the head is a sphere of its own, see head_center_offset
    (r"foot|ankle", 0.10, 0.8),   # feet without toes
)

SIMULATION_NAME = "simulation"   # the database's ground projection of the root: not drawn
PELVIS_RADIUS = 0.056            # a root of unknown size is the pelvis
GENERIC_LEAF_EXTENSION = 0.4   # of the parent bone's length, for leaves of unknown names
HEAD_CENTER_OFFSET = 0.55      # head sphere centre past the head joint, in head radii
HEIGHT_PER_TREE_DIAMETER = 1.0 / 1.35   # a human's longest joint-to-joint path (hand to toe) ~1.35 heights


def _match(name: str, table):
    low = name.lower()
    for row in table:
        if re.search(row[0], low):
            return row
    return None


def bone_lengths(parents, positions) -> np.ndarray:
    """(J,) distance of each joint to its parent (0 for roots) in one pose."""
    parents = np.asarray(parents, dtype=np.int64)
    p = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    lengths = np.zeros(len(parents))
    child = parents >= 0
    lengths[child] = np.linalg.norm(p[child] - p[parents[child]], axis=1)
    return np.where(np.isfinite(lengths), lengths, 0.0)


def _children(parents) -> list[list[int]]:
    kids = [[] for _ in parents]
    for j, p in enumerate(parents):
        if p >= 0:
            kids[p].append(j)
    return kids


def _post_order(parents) -> list[int]:
    """Joints with every child before its parent (BVH order already has parents first)."""
    order = np.argsort(_depths(parents), kind="stable")
    return list(order[::-1])


def _depths(parents) -> np.ndarray:
    depth = np.zeros(len(parents), dtype=np.int64)
    for j in range(len(parents)):
        k, d = j, 0
        while parents[k] >= 0 and d <= len(parents):
            k, d = parents[k], d + 1
        depth[j] = d
    return depth


def subtree_sizes(parents) -> np.ndarray:
    """(J,) number of joints in each joint's subtree, itself included."""
    parents = np.asarray(parents, dtype=np.int64)
    size = np.ones(len(parents))
    for j in _post_order(parents):
        if parents[j] >= 0:
            size[parents[j]] += size[j]
    return size


def estimate_height(parents, lengths) -> float:
    """A character's height from its bone lengths alone (any pose): the longest path between two
    joints through the tree, which for a human runs from a hand to a foot."""
    parents = np.asarray(parents, dtype=np.int64)
    lengths = np.asarray(lengths, dtype=np.float64)
    down = np.zeros(len(parents))      # longest path from a joint down to a leaf of its subtree
    diameter = 0.0
    for j in _post_order(parents):
        best = sorted((down[c] + lengths[c] for c in _children(parents)[j]), reverse=True)[:2]
        if best:
            down[j] = best[0]
            diameter = max(diameter, sum(best))
    return float(diameter * HEIGHT_PER_TREE_DIAMETER) if diameter > 0 else 1.0


def topology_radii(parents, lengths) -> np.ndarray:
    """(J,) radii / height of an unnamed skeleton: thick where a joint is far from the tips of its
    limbs and carries many of them (pelvis, spine), thin towards hands and feet."""
    parents = np.asarray(parents, dtype=np.int64)
    lengths = np.asarray(lengths, dtype=np.float64)
    kids = _children(parents)
    leaves = np.zeros(len(parents))
    to_tip = np.zeros(len(parents))   # path length to the farthest leaf below
    for j in _post_order(parents):
        if kids[j]:
            leaves[j] = sum(leaves[c] for c in kids[j])
            to_tip[j] = max(to_tip[c] + lengths[c] for c in kids[j])
        else:
            leaves[j] = 1.0
    share = leaves / max(leaves.max(), 1.0)
    reach = to_tip / max(to_tip.max(), 1e-12)
    return 0.014 + 0.032 * reach + 0.016 * np.sqrt(share)


def _known(body_radii, n: int) -> np.ndarray:
    """(J,) whether the caller gave a joint's radius (a finite ``body_radii`` entry)."""
    if body_radii is None:
        return np.zeros(n, dtype=bool)
    return np.isfinite(np.asarray(body_radii, dtype=np.float64).reshape(n))


def joint_radii(parents, body_radii=None, lengths=None, height: float = 1.0) -> np.ndarray:
    """(J,) radius of each joint sphere, in the units of ``height``. ``body_radii`` (J,): radius /
    height of the joints the caller knows (NaN for the others); the others (or all, without it)
    from the tree, a root of unknown size at least a pelvis's."""
    parents = np.asarray(parents, dtype=np.int64)
    if lengths is None:
        lengths = np.ones(len(parents))
    radii = topology_radii(parents, lengths)
    if body_radii is not None:
        known = _known(body_radii, len(parents))
        radii[known] = np.asarray(body_radii, dtype=np.float64).reshape(-1)[known]
        if len(parents) and parents[0] < 0 and radii[0] > 0 and not known[0]:
            radii[0] = max(radii[0], PELVIS_RADIUS)
    return radii * float(height)


def leaf_extensions(parents, names=None, lengths=None, height: float = 1.0, body_radii=None):
    """For each leaf joint: (length, end radius factor) of the segment that continues its parent
    bone past it, in the units of ``height``. Returns (lengths (J,), end factors (J,)); 0 for
    joints that are not leaves or get no extension. A leaf of a name not in
    ``NAME_LEAF_EXTENSIONS`` and of unknown size (``body_radii``) continues its bone a little."""
    parents = np.asarray(parents, dtype=np.int64)
    lengths = np.ones(len(parents)) if lengths is None else np.asarray(lengths, dtype=np.float64)
    is_leaf = np.ones(len(parents), dtype=bool)
    is_leaf[parents[parents >= 0]] = False
    is_leaf &= parents >= 0
    ext = np.zeros(len(parents))
    end = np.ones(len(parents))
    known = _known(body_radii, len(parents))
    for j in np.nonzero(is_leaf)[0]:
        row = _match(str(names[j]), NAME_LEAF_EXTENSIONS) if names is not None else None
        if row is not None:
            ext[j], end[j] = row[1] * height, row[2]
        elif not known[j]:
            ext[j], end[j] = GENERIC_LEAF_EXTENSION * lengths[j], 0.8
    return ext, end


def head_joints(parents, names=None) -> np.ndarray:
    """Indices of leaf joints named head/skull: drawn as a sphere centred past the joint."""
    if names is None:
        return np.zeros(0, dtype=np.int64)
    parents = np.asarray(parents, dtype=np.int64)
    is_leaf = np.ones(len(parents), dtype=bool)
    is_leaf[parents[parents >= 0]] = False
    return np.array([j for j, n in enumerate(names)
                     if is_leaf[j] and parents[j] >= 0 and re.search(r"head|skull", str(n).lower())
                     and not re.search(r"end|site|nub|top", str(n).lower())], dtype=np.int64)

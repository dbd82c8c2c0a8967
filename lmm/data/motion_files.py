"""One loader for every motion file format: :func:`load_motion` picks the reader by the file's extension and
returns the same :class:`~lmm.data.bvh.Animation` the BVH reader gives, so every command that takes a BVH
(manifests, ``view``, ``find``, ``compare``, ``physics``, ``check-data``, the studio's reference) takes them all.

Conventions of what comes back (BVH's own, so a glTF clip and a LAFAN1 take sit in one manifest):

- **BVH** (``.bvh``, ``.bvh.gz``): exactly as written, in the file's unit (:mod:`lmm.data.bvh`).
- **glTF 2.0** (``.glb``, ``.gltf``): metres in the file, returned in **centimetres** (:data:`MOTION_UNIT_M`,
  the shipped takes' unit and the manifests' default ``unit_scale`` 0.01); Y up as in BVH, no axis change;
  keyframes resampled to a fixed rate (:mod:`lmm.data.gltf`).
- **FBX** (``.fbx``): converted by ``ufbx`` to Y up, right-handed, centimetres, whatever the file's axis and
  unit settings; sampled at the file's frame rate (:mod:`lmm.data.fbx`).

Every problem in a file raises a :class:`~lmm.data.bvh.BVHError` (glTF and FBX raise its subclass
:class:`MotionFileError`), whose ``str()`` is one line naming the file; callers that already catch ``BVHError``
need nothing new. A missing optional reader (``pygltflib``, ``ufbx``) is a :class:`MissingExtra` (an
``InputError``): one line naming the file, the package and the extra that installs it.
"""
from __future__ import annotations

import importlib
import os

from lmm.data.bvh import Animation, BVHError
from lmm.errors import InputError

__all__ = ["load_motion", "MotionFileError", "MOTION_UNIT_M", "MissingExtra", "require_extra"]

#: metres per unit of the animations read from glTF and FBX
MOTION_UNIT_M = 0.01


class MotionFileError(BVHError):
    """A glTF or FBX file that cannot be read as a skeletal animation: ``str(e)`` is ``"{path}: {message}"``."""


class MissingExtra(InputError):
    """An optional package a format needs is not installed: one line naming the package and its extra."""


def require_extra(module: str, purpose: str, extra: str, path=None):
    """The optional ``module``, or :class:`MissingExtra` (naming ``path`` when given) saying which pyproject
    extra installs it; ``purpose`` is what needs it (``"reading FBX"``)."""
    try:
        return importlib.import_module(module)
    except ImportError:
        where = f"{os.fspath(path)}: " if path is not None else ""
        raise MissingExtra(f"{where}{purpose} needs {module}, which is not installed: pip install -e '.[{extra}]' "
                           "(scripts/setup test installs every extra)") from None


def load_motion(path) -> Animation:
    """The animation in ``path``, read by the reader its extension names (anything else is read as BVH, as
    before). Raises ``BVHError`` (one line) for a bad file, ``OSError`` for one that cannot be opened."""
    low = os.fspath(path).lower()
    if low.endswith((".glb", ".gltf")):
        from lmm.data import gltf
        return gltf.load(path)
    if low.endswith(".fbx"):
        from lmm.data import fbx
        return fbx.load(path)
    from lmm.data import bvh
    return bvh.load(path)


def depth_first(parents_of: dict, roots: list) -> list:
    """Node ids in depth-first order from ``roots`` (children in id order), so every parent comes first."""
    children: dict = {}
    for n, p in parents_of.items():
        children.setdefault(p, []).append(n)
    order, stack = [], list(reversed(roots))
    while stack:
        n = stack.pop()
        order.append(n)
        stack.extend(sorted(children.get(n, []), reverse=True))
    return order


def from_sampled(names, parents, offsets, rotations, positions, moved, fps: float, path) -> Animation:
    """An :class:`Animation` from sampled local rotations (F, J, 4; w, x, y, z) and translations (F, J, 3) in
    centimetres: joints in ``moved`` (and every root) get position channels, the others their ``offsets``;
    rotations as ``Zrotation Yrotation Xrotation`` (BVH's usual order)."""
    import numpy as np

    moved = sorted(set(int(j) for j in moved) | {j for j, p in enumerate(parents) if p < 0})
    if not np.isfinite(rotations).all() or not np.isfinite(positions).all():
        raise MotionFileError("the animation's values are not finite", path)
    anim = Animation.from_local(names, parents, offsets, rotations, positions, 1.0 / fps, rotation_order="zyx",
                                position_joints=moved)
    anim.path = os.fspath(path)
    return anim

"""Writing an :class:`~lmm.data.bvh.Animation` as a glTF 2.0 binary (``.glb``) with ``pygltflib``.

What is written (the conventions glTF requires or viewers expect):

- one node per joint, named as in the file, in a hierarchy that follows ``parents``; the rest translation of a
  node is the joint's offset, its rest rotation the identity (the BVH rest pose);
- a skin whose joints are those nodes (inverse bind matrices of that rest pose);
- one animation, ``"take"``: a rotation channel for every joint and a translation channel for every joint
  with position channels in the file, one keyframe per frame at the file's rate (LINEAR), so a reader that
  samples at the keyframes gets the frames back exactly (float32);
- positions in metres (``unit_scale`` metres per file unit), axes as in the file (BVH here is Y up and
  right-handed, as glTF is: nothing is rotated);
- optionally (``mesh="capsules"``) a body of capsules, one per bone, skinned rigidly to the bone's parent joint,
  so the motion plays in any glTF viewer (a skeleton alone draws nothing there).

``pygltflib`` is the ``formats`` extra; without it :func:`require_pygltflib` says how to install it in one line.
"""
from __future__ import annotations

import os

import numpy as np

from lmm import kinematics

__all__ = ["save_glb", "require_pygltflib", "capsule_body"]

_FLOAT, _USHORT, _UINT = 5126, 5123, 5125
_ARRAY_BUFFER, _ELEMENT_ARRAY_BUFFER = 34962, 34963


def require_pygltflib():
    """The ``pygltflib`` module, or a one-line :class:`~lmm.data.motion_files.MissingExtra`."""
    from lmm.data.motion_files import require_extra
    return require_extra("pygltflib", "writing glTF", "formats")


class _Blob:
    """The binary chunk: arrays appended 4-byte aligned, each with its buffer view and accessor."""

    def __init__(self, g):
        self.g, self.parts, self.size = g, [], 0

    def add(self, array: np.ndarray, type_: str, component: int, target: int | None = None,
            with_bounds: bool = False) -> int:
        lib = require_pygltflib()
        data = np.ascontiguousarray(array).tobytes()
        pad = (-self.size) % 4
        self.parts.append(b"\0" * pad)
        self.size += pad
        self.g.bufferViews.append(lib.BufferView(buffer=0, byteOffset=self.size, byteLength=len(data), target=target))
        self.parts.append(data)
        self.size += len(data)
        rows = array.reshape(len(array), -1)
        accessor = lib.Accessor(bufferView=len(self.g.bufferViews) - 1, componentType=component, count=len(array),
                                type=type_)
        if with_bounds:
            accessor.min = [float(v) for v in rows.min(axis=0)]
            accessor.max = [float(v) for v in rows.max(axis=0)]
        self.g.accessors.append(accessor)
        return len(self.g.accessors) - 1

    def bytes(self) -> bytes:
        out = b"".join(self.parts)
        return out + b"\0" * ((-len(out)) % 4)


def _capsule(a: np.ndarray, b: np.ndarray, radius: float, around: int = 12, rings: int = 4):
    """Vertices, normals and triangles of a capsule from ``a`` to ``b`` (a cylinder with two half spheres)."""
    axis = b - a
    length = float(np.linalg.norm(axis))
    y = axis / length
    helper = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    x = np.cross(helper, y)
    x /= np.linalg.norm(x)
    z = np.cross(x, y)
    phis = np.linspace(0.0, 2.0 * np.pi, around, endpoint=False)
    # latitude rings without the poles: the lower half sphere around a, then the upper one around b; each
    # pole is one vertex with a fan of triangles (a ring collapsed to a point would make empty triangles)
    steps = np.linspace(-np.pi / 2, 0.0, rings + 1)[1:]
    lats = np.concatenate([steps, -steps[::-1]])
    centres = [a] * rings + [b] * rings
    verts, norms = [a - radius * y], [-y]
    for lat, c in zip(lats, centres):
        for phi in phis:
            n = np.cos(lat) * (np.cos(phi) * x + np.sin(phi) * z) + np.sin(lat) * y
            norms.append(n)
            verts.append(c + radius * n)
    verts.append(b + radius * y)
    norms.append(y)
    top = len(verts) - 1
    ring = lambda r, k: 1 + r * around + k % around      # noqa: E731 - vertex k of ring r
    tris = [(0, ring(0, k), ring(0, k + 1)) for k in range(around)]
    for r in range(len(lats) - 1):
        for k in range(around):
            tris += [(ring(r, k), ring(r + 1, k), ring(r, k + 1)), (ring(r, k + 1), ring(r + 1, k), ring(r + 1, k + 1))]
    last = len(lats) - 1
    tris += [(ring(last, k), top, ring(last, k + 1)) for k in range(around)]
    return np.array(verts), np.array(norms), np.array(tris)


def capsule_body(names, parents, rest: np.ndarray, height: float):
    """A capsule per bone of the rest pose ``rest`` (J, 3, metres), bound to the bone's parent joint: vertices,
    normals, triangles and each vertex's joint. Radii from :func:`lmm.skeleton.body_radii`, a fraction of the
    character's ``height`` in metres (unnamed parts 3 %); the rest pose need not stand (LAFAN1's lies along x)."""
    from lmm.skeleton import body_radii

    radii = np.nan_to_num(body_radii(names), nan=0.03) * height
    V, N, T, joints = [], [], [], []
    count = 0
    for j, p in enumerate(parents):
        if p < 0 or np.linalg.norm(rest[j] - rest[p]) < 1e-6 or radii[p] <= 0:
            continue
        r = min(float(radii[p]), 0.5 * float(np.linalg.norm(rest[j] - rest[p])))
        v, n, t = _capsule(rest[p], rest[j], r)
        V.append(v)
        N.append(n)
        T.append(t + count)
        joints.append(np.full(len(v), p))
        count += len(v)
    if not V:
        return None
    return np.concatenate(V), np.concatenate(N), np.concatenate(T), np.concatenate(joints)


def save_glb(path, anim, unit_scale: float, mesh: str = "capsules") -> None:
    """Write ``anim`` to ``path`` as a ``.glb`` (see the module doc). ``unit_scale``: metres per file unit."""
    lib = require_pygltflib()
    from lmm.data.atomic import write_bytes_atomic

    if mesh not in ("capsules", "none"):
        raise ValueError(f"mesh must be 'capsules' or 'none', got {mesh!r}")
    J, F = anim.n_joints, anim.n_frames
    parents = np.asarray(anim.parents)
    offsets = anim.offsets * unit_scale
    rest = kinematics.forward_kinematics(np.tile([1.0, 0, 0, 0], (1, J, 1)), offsets[None], parents)[1][0]
    g = lib.GLTF2(asset=lib.Asset(version="2.0", generator="lmm-studio export-gltf"))
    blob = _Blob(g)
    for j in range(J):
        g.nodes.append(lib.Node(name=anim.names[j], translation=[float(v) for v in offsets[j]],
                                children=[int(c) for c in np.flatnonzero(parents == j)]))
    roots = [int(j) for j in np.flatnonzero(parents < 0)]
    ibm = np.tile(np.eye(4, dtype=np.float32), (J, 1, 1))
    ibm[:, 3, :3] = -rest          # column-major: the translation is the last column
    g.skins.append(lib.Skin(name="skeleton", joints=list(range(J)), skeleton=roots[0] if len(roots) == 1 else None,
                            inverseBindMatrices=blob.add(ibm, "MAT4", _FLOAT)))
    scene_nodes = list(roots)
    if mesh == "capsules":
        standing = anim.global_positions()[0] * unit_scale if F > 0 else rest     # the first frame's height
        height = float(np.ptp(standing[:, 1])) or float(np.ptp(rest)) or 1.0
        body = capsule_body(anim.names, parents, rest, height)
        if body is not None:
            v, n, t, jo = body
            attrs = lib.Attributes(
                POSITION=blob.add(v.astype(np.float32), "VEC3", _FLOAT, _ARRAY_BUFFER, with_bounds=True),
                NORMAL=blob.add(n.astype(np.float32), "VEC3", _FLOAT, _ARRAY_BUFFER),
                JOINTS_0=blob.add(np.stack([jo, 0 * jo, 0 * jo, 0 * jo], 1).astype(np.uint16), "VEC4", _USHORT,
                                  _ARRAY_BUFFER),
                WEIGHTS_0=blob.add(np.tile(np.float32([1, 0, 0, 0]), (len(v), 1)), "VEC4", _FLOAT, _ARRAY_BUFFER))
            prim = lib.Primitive(attributes=attrs, indices=blob.add(t.reshape(-1).astype(np.uint32), "SCALAR", _UINT,
                                                                    _ELEMENT_ARRAY_BUFFER))
            g.meshes.append(lib.Mesh(name="capsules", primitives=[prim]))
            g.nodes.append(lib.Node(name="body", mesh=0, skin=0))
            scene_nodes.append(len(g.nodes) - 1)
    g.scenes.append(lib.Scene(name="scene", nodes=scene_nodes))
    g.scene = 0
    if F > 0:
        times = blob.add((np.arange(F) * anim.frame_time).astype(np.float32)[:, None], "SCALAR", _FLOAT,
                         with_bounds=True)
        rot = anim.local_rotations()[..., [1, 2, 3, 0]].astype(np.float32)    # glTF: x, y, z, w
        pos = (anim.local_positions() * unit_scale).astype(np.float32)
        moved = [j for j in range(J) if any(c.lower().endswith("position") for c in anim.channels[j])]
        samplers, channels = [], []
        for j in range(J):
            for path_, values, type_ in (("rotation", rot[:, j], "VEC4"), ("translation", pos[:, j], "VEC3")):
                if path_ == "translation" and j not in moved:
                    continue
                samplers.append(lib.AnimationSampler(input=times, output=blob.add(values, type_, _FLOAT),
                                                     interpolation="LINEAR"))
                channels.append(lib.AnimationChannel(sampler=len(samplers) - 1,
                                                     target=lib.AnimationChannelTarget(node=j, path=path_)))
        g.animations.append(lib.Animation(name="take", samplers=samplers, channels=channels))
    data = blob.bytes()
    g.buffers.append(lib.Buffer(byteLength=len(data)))
    g.set_binary_blob(data)
    write_bytes_atomic(os.fspath(path), b"".join(g.save_to_bytes()))

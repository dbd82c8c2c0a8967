"""Reading a skeletal animation from glTF 2.0 (``.glb``, ``.gltf`` with embedded or side-by-side buffers).

What is read, and how it becomes BVH's :class:`~lmm.data.bvh.Animation`:

- **The skeleton** is the joints of the first skin (a glTF without a skin is refused: a node animation is not
  a skeleton). Each joint's parent is its nearest ancestor among the joints; the static transforms of nodes in
  between, and of the nodes above the skeleton's root (an "Armature" node with a rotation or a 0.01 scale),
  are folded into the joint's own (node ``matrix`` or TRS). Joints are put in depth-first order; names kept
  (an unnamed node is ``Node_<index>``, as Blender names it).
- **Scale:** uniform rest scales are folded into the translations below them; a non-uniform one uses its
  geometric mean; animated scale channels are ignored.
- **The motion** is the first animation that moves a joint: its rotation and translation channels, with
  LINEAR (slerp for rotations), STEP and CUBICSPLINE interpolation, sampled at a fixed rate: the keyframes'
  own rate when they are evenly spaced at 24..240 per second (a file written by ``export-gltf``: its frame time
  comes back to float32's precision), else
  :data:`DEFAULT_FPS`. A joint without a channel keeps its rest transform.
- **Units and axes:** glTF is metres, Y up, right-handed; returned in centimetres
  (:data:`lmm.data.motion_files.MOTION_UNIT_M`) with the axes unchanged (BVH here is Y up too).

Every problem raises :class:`~lmm.data.motion_files.MotionFileError`, one line naming the file.
"""
from __future__ import annotations

import json
import os
import struct
import warnings

import numpy as np

from lmm import quat
from lmm.data.bvh import Animation
from lmm.data.motion_files import MOTION_UNIT_M, MotionFileError, depth_first, from_sampled, require_extra
from lmm.data.reading import open_regular, read_limited
from lmm.errors import InputError

__all__ = ["load", "DEFAULT_FPS", "MAX_SAMPLES", "MAX_FILE_BYTES"]

#: the rate unevenly spaced keyframes are sampled at
DEFAULT_FPS = 30.0
#: largest file read (its buffers are held in memory while the animation is sampled)
MAX_FILE_BYTES = 512 * 2**20
#: most frames x joints sampled (the BVH reader's ``MAX_JOINT_FRAMES``)
MAX_SAMPLES = 3_000_000
_COMPONENTS = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def _json_text_of_glb(data: bytes, path) -> str:
    """The JSON chunk of a ``.glb``, after checking its header against the bytes there are."""
    if len(data) < 20:
        raise _error(path, f"a truncated glb ({len(data)} bytes, no header)")
    version, length, chunk, kind = struct.unpack_from("<IIII", data, 4)
    if version != 2:
        raise _error(path, f"a glb of version {version}, not 2")
    if length > len(data) or 20 + chunk > len(data):
        raise _error(path, f"a truncated glb ({len(data)} bytes of the {length} its header declares)")
    if kind != 0x4E4F534A:  # "JSON"
        raise _error(path, "not a glTF 2.0 file (the glb's first chunk is not JSON)")
    return data[20:20 + chunk].decode("utf-8", errors="replace")


def _error(path, message):
    return MotionFileError(message, path)


class _Reader:
    """The parsed file and its accessors as float64 arrays."""

    def _json_text(self, data: bytes) -> str:
        if data[:4] == b"glTF":
            return _json_text_of_glb(data, self.path)
        return data.decode("utf-8", errors="replace")

    def __init__(self, path):
        pygltflib = require_extra("pygltflib", "reading glTF", "formats", path)
        self.path = os.fspath(path)
        # a regular file only (a FIFO or device is one line, and never blocks); OSError for a missing one
        with open_regular(self.path, "glTF file") as f:
            if os.fstat(f.fileno()).st_size > MAX_FILE_BYTES:
                raise _error(path, f"the file is larger than {MAX_FILE_BYTES >> 20} MiB")
            data = f.read(MAX_FILE_BYTES + 1)
        text = self._json_text(data)
        try:
            meta = json.loads(text)
        except ValueError:
            raise _error(path, "not a glTF 2.0 file (its JSON does not parse)") from None
        version = meta.get("asset", {}).get("version") if isinstance(meta, dict) and isinstance(
            meta.get("asset"), dict) else None
        if not str(version).startswith("2"):
            raise _error(path, "not a glTF 2.0 file (no asset.version 2.x)")
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("ignore")
                self.g = (pygltflib.GLTF2.load_from_bytes(data) if data[:4] == b"glTF"
                          else pygltflib.GLTF2.from_json(text))
        except Exception as e:  # pygltflib raises whatever its parser met: a message, not a trace
            raise _error(path, f"not a glTF 2.0 file ({type(e).__name__}: {str(e)[:120]})") from None
        self._buffers: dict[int, bytes] = {}

    def buffer(self, i: int) -> bytes:
        if i not in self._buffers:
            b = self.g.buffers[i]
            if b.uri is None:
                data = self.g.binary_blob()
            elif b.uri.startswith("data:"):
                import base64
                data = base64.b64decode(b.uri.split(",", 1)[1])
            else:
                side = os.path.join(os.path.dirname(self.path), b.uri)
                try:
                    data = read_limited(side, MAX_FILE_BYTES, "glTF buffer")
                except OSError as e:
                    raise _error(self.path, f"buffer {b.uri!r}: {e.strerror}") from None
                except InputError as e:
                    raise _error(self.path, f"buffer {b.uri!r}: {e}") from None
            if data is None or len(data) < b.byteLength:
                raise _error(self.path, f"buffer {i} has {0 if data is None else len(data)} bytes, "
                                        f"{b.byteLength} declared (a truncated file?)")
            self._buffers[i] = data
        return self._buffers[i]

    def accessor(self, i: int) -> np.ndarray:
        """Accessor ``i`` as a (count, width) float64 array (normalized integers scaled as the spec says)."""
        try:
            a = self.g.accessors[i]
            if a.sparse is not None or a.bufferView is None:
                raise _error(self.path, f"accessor {i} is sparse or has no buffer view (not read)")
            v = self.g.bufferViews[a.bufferView]
            dtype, width = np.dtype(_COMPONENTS[a.componentType]), _WIDTH[a.type]
            stride = v.byteStride or dtype.itemsize * width
            start = (v.byteOffset or 0) + (a.byteOffset or 0)
            data = self.buffer(v.buffer)
            end = start + stride * (a.count - 1) + dtype.itemsize * width if a.count else start
            if end > (v.byteOffset or 0) + v.byteLength or end > len(data):
                raise _error(self.path, f"accessor {i} reaches past its buffer (a truncated file?)")
            raw = np.lib.stride_tricks.as_strided(np.frombuffer(data, np.uint8, end - start, start),
                                                  (a.count, dtype.itemsize * width), (stride, 1))
            out = np.ascontiguousarray(raw).view(dtype).reshape(a.count, width).astype(np.float64)
        except (IndexError, KeyError, TypeError, ValueError) as e:
            if isinstance(e, MotionFileError):
                raise
            raise _error(self.path, f"accessor {i} is malformed ({type(e).__name__})") from None
        if a.normalized and dtype.kind in "iu":
            out = np.maximum(out / np.iinfo(dtype).max, -1.0)
        return out


def _local(node) -> tuple[np.ndarray, np.ndarray, float]:
    """A node's rest rotation (w, x, y, z), translation and uniform scale."""
    if node.matrix is not None:
        m = np.asarray(node.matrix, dtype=np.float64).reshape(4, 4).T       # column-major
        s = np.linalg.norm(m[:3, :3], axis=0)
        r = quat.from_matrix(m[:3, :3] / np.where(s > 0, s, 1.0))
        return r, m[:3, 3].copy(), float(np.prod(s)) ** (1 / 3)
    r = np.array(node.rotation if node.rotation is not None else [0, 0, 0, 1.0], dtype=np.float64)[[3, 0, 1, 2]]
    t = np.array(node.translation if node.translation is not None else [0, 0, 0.0], dtype=np.float64)
    s = np.abs(np.array(node.scale if node.scale is not None else [1, 1, 1.0], dtype=np.float64))
    return quat.normalize(r), t, float(np.prod(s)) ** (1 / 3)


def _sample(r: _Reader, sampler, times: np.ndarray, is_rotation: bool) -> np.ndarray:
    """One sampler's values at ``times`` (clamped to its keyframes)."""
    keys = r.accessor(sampler.input)[:, 0]
    values = r.accessor(sampler.output)
    mode = sampler.interpolation or "LINEAR"
    cubic = mode == "CUBICSPLINE"
    if len(keys) == 0 or len(values) != len(keys) * (3 if cubic else 1) or np.any(np.diff(keys) < 0):
        raise _error(r.path, f"an animation sampler has {len(keys)} keyframes and {len(values)} values, "
                             "or times that go backwards")
    if is_rotation:
        values = values[:, [3, 0, 1, 2]]
    tangents_in = tangents_out = None
    if cubic:
        tangents_in, values, tangents_out = values[0::3], values[1::3], values[2::3]
    i = np.clip(np.searchsorted(keys, times, side="right") - 1, 0, len(keys) - 1)
    k = np.minimum(i + 1, len(keys) - 1)
    span = keys[k] - keys[i]
    u = np.clip(np.where(span > 0, (times - keys[i]) / np.where(span > 0, span, 1.0), 0.0), 0.0, 1.0)[:, None]
    if mode == "STEP":
        out = values[i]
    elif cubic:
        u2, u3 = u * u, u * u * u
        d = span[:, None]
        out = ((2 * u3 - 3 * u2 + 1) * values[i] + (u3 - 2 * u2 + u) * d * tangents_out[i]
               + (-2 * u3 + 3 * u2) * values[k] + (u3 - u2) * d * tangents_in[k])
    elif is_rotation:
        out = quat.slerp(quat.normalize(values[i]), quat.normalize(values[k]), u[:, 0])
    else:
        out = values[i] + u * (values[k] - values[i])
    return quat.normalize(out) if is_rotation else out


def _rate(key_times: list[np.ndarray]) -> tuple[float, np.ndarray | None]:
    """The keyframes' own rate and times when evenly spaced at 24..240 per second (sampled at exactly those
    times), else :data:`DEFAULT_FPS` and None."""
    t = np.unique(np.concatenate(key_times))
    if len(t) < 3:
        return DEFAULT_FPS, None
    dt = np.diff(t)
    step = (t[-1] - t[0]) / (len(t) - 1)       # the mean step: float32 keyframe times round each one
    if 1 / 240 <= step <= 1 / 24 and np.allclose(dt, step, rtol=1e-3, atol=1e-5):
        return float(1.0 / step), t
    return DEFAULT_FPS, None


def load(path) -> Animation:
    """The first skin's animation in a glTF 2.0 file as an :class:`~lmm.data.bvh.Animation` (module doc)."""
    r = _Reader(path)
    g = r.g
    skin = next((s for s in g.skins if s.joints), None)
    if skin is None:
        raise _error(path, "has no skin (no skeleton): only skeletal animations are read")
    n_nodes = len(g.nodes)
    if any(not 0 <= j < n_nodes for j in skin.joints):
        raise _error(path, "a skin names a node that does not exist")
    joints = set(skin.joints)
    parent_node = {}
    for i, node in enumerate(g.nodes):
        for c in node.children or []:
            if 0 <= c < n_nodes:
                parent_node[c] = i
    rests = [_local(node) for node in g.nodes]

    # each joint's nearest joint ancestor, and the static transform of the nodes in between folded in
    joint_parent, fold = {}, {}
    for j in joints:
        rot, pos, scale = quat.identity(), np.zeros(3), 1.0      # the chain above j, as one transform
        n, seen = parent_node.get(j), 0
        while n is not None and n not in joints:
            nr, nt, ns = rests[n]
            pos = nt + quat.mul_vec(nr, ns * pos)
            rot, scale = quat.mul(nr, rot), ns * scale
            n, seen = parent_node.get(n), seen + 1
            if seen > n_nodes:
                raise _error(path, "its node hierarchy has a cycle")
        joint_parent[j], fold[j] = n, (rot, pos, scale)
    order = depth_first(joint_parent, sorted(j for j in joints if joint_parent[j] is None))
    if len(order) != len(joints):
        raise _error(path, "its skeleton's hierarchy has a cycle")
    index = {n: k for k, n in enumerate(order)}
    parents = np.array([index[joint_parent[n]] if joint_parent[n] is not None else -1 for n in order])
    names = [g.nodes[n].name or f"Node_{n}" for n in order]

    animation = next((a for a in g.animations
                      if any(c.target.node in joints and c.target.path in ("rotation", "translation")
                             for c in a.channels if c.target is not None)), None)
    if animation is None:
        raise _error(path, "has no animation of its skeleton (only animated skeletons are read)")
    channels = [c for c in animation.channels if c.target is not None and c.target.node in joints
                and c.target.path in ("rotation", "translation")]
    try:
        samplers = [animation.samplers[c.sampler] for c in channels]
    except (IndexError, TypeError):
        raise _error(path, "an animation channel names a sampler that does not exist") from None
    key_times = [r.accessor(s.input)[:, 0] for s in samplers]
    if any(len(t) == 0 or not np.isfinite(t).all() for t in key_times):
        raise _error(path, "an animation sampler has no keyframe times, or times that are not finite")
    start = min(float(t.min()) for t in key_times if len(t))
    stop = max(float(t.max()) for t in key_times if len(t))
    fps, times = _rate(key_times)
    F = len(times) if times is not None else int(round((stop - start) * fps)) + 1
    if F * len(order) > MAX_SAMPLES:
        raise _error(path, f"{F} frames x {len(order)} joints is more than {MAX_SAMPLES} joint-frames")
    if times is None:
        times = start + np.arange(F) / fps

    J = len(order)
    rot = np.empty((F, J, 4))
    pos = np.empty((F, J, 3))
    for k, n in enumerate(order):
        rot[:, k], pos[:, k] = rests[n][0], rests[n][1]
    moved = set()
    for c, s in zip(channels, samplers):
        k = index[c.target.node]
        if c.target.path == "rotation":
            rot[:, k] = _sample(r, s, times, True)
        else:
            pos[:, k] = _sample(r, s, times, False)
            moved.add(k)
    # fold the in-between nodes, then the scales above each joint into its translation, then to centimetres
    scale_above = np.ones(J)
    for k, n in enumerate(order):
        frot, fpos, fscale = fold[n]
        p = parents[k]
        above = (scale_above[p] * rests[order[p]][2] if p >= 0 else 1.0)
        pos[:, k] = fpos + quat.mul_vec(frot, fscale * pos[:, k])
        rot[:, k] = quat.mul(frot, rot[:, k])
        pos[:, k] *= above
        scale_above[k] = above * fscale
    pos /= MOTION_UNIT_M
    return from_sampled(names, parents, pos[0].copy(), rot, pos, moved, fps, path)

"""The motion database: every frame of every clip range, at 60 Hz, mirrored, with a simulation bone.

Built from a manifest (see :mod:`lmm.data.manifest`) in the order of the reference pipeline:
BVH -> local rotations/positions (unit scaled) -> trim to ranges -> cubic resample to the target fps
-> left/right mirror copy -> prepend the simulation (root) bone -> velocities and angular velocities
-> foot contacts. Bone 0 is always the simulation bone; its position/velocity are in world space and
every other bone is local to its parent (velocities and angular velocities in the parent's frame).

The result is cached as an archive (:mod:`lmm.data.archive`; its per-frame arrays memory-mapped on
load, see :mod:`lmm.data.npz_mmap`) keyed by a hash of the file contents and settings; the
cache file's name is made of that hash only (never of text from the manifest), and it is written
atomically. A build stops with a ManifestError before resampling a range that would take the database
past :data:`MAX_DATABASE_FRAMES` frames.
"""
from __future__ import annotations

import contextlib
import hashlib
import json
import os
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lmm import DEFAULT_MANIFEST, quat
from lmm.data import bvh
from lmm.data import archive
from lmm.data.derived import file_digest as _file_digest
from lmm.filters import catmull_rom, central_difference, median_filter, savgol_smooth
from lmm.data.manifest import Manifest, ManifestError, load_manifest
from lmm.data.npz_mmap import worth_mapping
from lmm.kinematics import forward_kinematics, forward_kinematics_velocity, global_to_local
from lmm.errors import InputError

DB_FORMAT_VERSION = 5  # 5: mirrored clips keep the original bone offsets
SIMULATION_BONE = "Simulation"
#: Most frames in a built database (mirrored copies included): 4.6 hours at 60 fps, twice every take of
#: the LAFAN1 folder mirrored (501,918 frames) and 17x the shipped set (57,500). The build works one take
#: at a time (a few hundred MB at its peak for the longest take) and writes about 1.2 KB a frame (23
#: bones) to the cache, which the runtime memory-maps: 1.2 GB of cache at this limit.
MAX_DATABASE_FRAMES = 1_000_000
#: Fewest frames in a range after resampling: the velocities and the trajectory features need them.
MIN_RANGE_FRAMES = 4


class DatabaseError(InputError):
    """A file that is not a usable database (or cache); ``str(e)`` names the file."""


@dataclass
class Database:
    names: list[str]
    parents: np.ndarray            # (J,) int64, parents[0] == -1 (simulation bone)
    positions: np.ndarray          # (N, J, 3) float32, local (bone 0: world)
    rotations: np.ndarray          # (N, J, 4) float32, local (bone 0: world)
    velocities: np.ndarray         # (N, J, 3) float32, local, m/s
    angular_velocities: np.ndarray  # (N, J, 3) float32, local, rad/s
    contacts: np.ndarray           # (N, 2) bool: left toe, right toe
    toe_speeds: np.ndarray         # (N, 2) float32: median-filtered toe speed (m/s) the contacts come from
    range_starts: np.ndarray       # (R,) int64
    range_stops: np.ndarray        # (R,) int64 (exclusive)
    range_names: list[str]
    range_mirrored: np.ndarray     # (R,) bool
    fps: float = 60.0
    bone_roles: dict[str, str] = field(default_factory=dict)  # role -> bone name (hips, left_foot, ...)
    mirror_map: np.ndarray | None = None  # (J,) bone index of each bone's mirror counterpart
    key: str = ""                  # hash of inputs + settings (what trained networks are tied to)
    build_fingerprint: str = ""    # hash of the build code (cache validity only, see build_code_fingerprint)
    name: str = "dataset"
    range_tags: list[tuple[str, ...]] = field(default_factory=list)  # (R,) the manifest's tags of each range
    tag_names: list[str] = field(default_factory=list)               # (T,) sorted
    frame_tags: np.ndarray | None = None  # (N, T) bool: frame_tags[i, t] when frame i's range has tag_names[t]
    feature_schema: list[dict] = field(default_factory=list)  # the manifest's feature channels (empty: shipped)
    source_path: Path | None = field(default=None, repr=False, compare=False)  # the file it was loaded from

    # -- sizes -----------------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return int(self.positions.shape[0])

    @property
    def n_bones(self) -> int:
        return int(self.positions.shape[1])

    @property
    def dt(self) -> float:
        return 1.0 / self.fps

    @property
    def seconds(self) -> float:
        return self.n_frames / self.fps

    @property
    def n_ranges(self) -> int:
        return int(len(self.range_starts))

    def pose_bytes(self) -> int:
        """Bytes of the pose data a motion matching runtime keeps in memory."""
        return int(sum(a.nbytes for a in (self.positions, self.rotations, self.velocities,
                                          self.angular_velocities, self.contacts, self.range_starts,
                                          self.range_stops)))

    def bone(self, name_or_role: str) -> int:
        name = self.bone_roles.get(name_or_role, name_or_role)
        try:
            return self.names.index(name)
        except ValueError:
            raise KeyError(f"no bone named {name_or_role!r} in the database") from None

    # -- tags ------------------------------------------------------------------------------
    def tag_mask(self, tags) -> np.ndarray:
        """(N,) bool: frames whose range has any of ``tags`` (a name or a list; unknown names match nothing)."""
        tags = [tags] if isinstance(tags, str) else list(tags)
        cols = [self.tag_names.index(t) for t in tags if t in self.tag_names]
        if not cols or self.frame_tags is None:
            return np.zeros(self.n_frames, dtype=bool)
        return self.frame_tags[:, cols].any(axis=1)

    def tags_of(self, frame: int) -> tuple[str, ...]:
        """The tags of the range that holds ``frame`` (empty when none or out of range)."""
        if not 0 <= frame < self.n_frames or not self.range_tags:
            return ()
        return tuple(self.range_tags[int(self.range_index(frame))])

    def set_tags(self, range_tags) -> None:
        """Per-range tags (R lists, in range order) -> ``range_tags``, ``tag_names`` and ``frame_tags``."""
        range_tags = [tuple(t) for t in range_tags]
        if len(range_tags) != self.n_ranges:
            raise DatabaseError(f"{len(range_tags)} tag lists for {self.n_ranges} ranges")
        self.range_tags = range_tags
        self.tag_names = sorted({t for tags in range_tags for t in tags})
        per_range = np.array([[t in tags for t in self.tag_names] for tags in range_tags], dtype=bool)
        per_range = per_range.reshape(self.n_ranges, len(self.tag_names))
        self.frame_tags = np.repeat(per_range, self.range_stops - self.range_starts, axis=0)

    # -- frame bookkeeping -----------------------------------------------------------------
    def range_index(self, frames) -> np.ndarray:
        """Index of the range that holds each frame."""
        return np.searchsorted(self.range_stops, np.asarray(frames), side="right")

    def range_stop_of(self, frames) -> np.ndarray:
        return self.range_stops[self.range_index(frames)]

    def future_frame(self, frames, offset: int) -> np.ndarray:
        """frames + offset, clamped to the last frame of the frame's own range."""
        frames = np.asarray(frames)
        return np.minimum(frames + offset, self.range_stop_of(frames) - 1)

    # -- kinematics ------------------------------------------------------------------------
    def global_transforms(self, frames=slice(None)):
        """Global rotations (n, J, 4) and positions (n, J, 3) of the given frames (float64)."""
        return forward_kinematics(self.rotations[frames].astype(np.float64),
                                  self.positions[frames].astype(np.float64), self.parents)

    FK_CHUNK_FRAMES = 8192

    def global_transforms_of(self, bones, frames=slice(None)):
        """Global rotations (n, len(bones), 4) and positions (n, len(bones), 3) of ``bones`` only (float64):
        forward kinematics over their ancestors, not the whole skeleton (bit-identical to the same
        columns of :meth:`global_transforms`, with a fraction of the work and memory)."""
        bones = [int(b) for b in bones]
        needed = set()
        for b in bones:
            while b >= 0 and b not in needed:
                needed.add(b)
                b = int(self.parents[b])
        chain = sorted(needed)  # parents come before children
        slot = {j: i for i, j in enumerate(chain)}
        sub_parents = np.array([slot[int(self.parents[j])] if self.parents[j] >= 0 else -1 for j in chain])
        cols = [slot[b] for b in bones]
        index = np.arange(self.n_frames)[frames]
        out_rot = np.empty((len(index), len(bones), 4), dtype=np.float64)
        out_pos = np.empty((len(index), len(bones), 3), dtype=np.float64)
        # a few thousand frames at a time: the intermediates stay in the CPU cache (5x faster at 0.5 M
        # frames than one pass); every frame's arithmetic is the same, so are the results
        for start in range(0, len(index), self.FK_CHUNK_FRAMES):
            part = index[start:start + self.FK_CHUNK_FRAMES]
            rot = np.asarray(self.rotations[part])[:, chain].astype(np.float64)
            pos = np.asarray(self.positions[part])[:, chain].astype(np.float64)
            g_rot, g_pos = forward_kinematics(rot, pos, sub_parents)
            out_rot[start:start + len(part)] = g_rot[:, cols]
            out_pos[start:start + len(part)] = g_pos[:, cols]
        return out_rot, out_pos

    def global_kinematics(self, frames=slice(None)):
        """Global rotations, positions, velocities and angular velocities (float64)."""
        return forward_kinematics_velocity(
            self.rotations[frames].astype(np.float64), self.positions[frames].astype(np.float64),
            self.velocities[frames].astype(np.float64), self.angular_velocities[frames].astype(np.float64),
            self.parents)

    # -- persistence -----------------------------------------------------------------------
    def to_archive(self) -> tuple[dict[str, np.ndarray], dict]:
        """The arrays and the metadata of the database's file (:mod:`lmm.data.archive`). The bone roles
        are pairs, so their order (the manifest's) survives the archive's sorted keys."""
        arrays = {
            "parents": self.parents, "positions": self.positions, "rotations": self.rotations,
            "velocities": self.velocities, "angular_velocities": self.angular_velocities,
            "contacts": self.contacts, "toe_speeds": self.toe_speeds, "range_starts": self.range_starts,
            "range_stops": self.range_stops, "range_mirrored": self.range_mirrored,
            "mirror_map": self.mirror_map if self.mirror_map is not None else np.arange(self.n_bones),
            "frame_tags": (self.frame_tags if self.frame_tags is not None
                           else np.zeros((self.n_frames, 0), dtype=bool)),
        }
        metadata = {
            "format_version": DB_FORMAT_VERSION, "names": list(self.names), "range_names": list(self.range_names),
            "fps": float(self.fps), "bone_roles": [[role, bone] for role, bone in self.bone_roles.items()],
            "key": self.key, "name": self.name, "build_fingerprint": self.build_fingerprint,
            "range_tags": [list(t) for t in self.range_tags], "tag_names": list(self.tag_names),
            "feature_schema": self.feature_schema,
        }
        return arrays, metadata

    def save(self, path) -> None:
        archive.write(path, *self.to_archive())  # atomic: a killed build never leaves a half-written cache

    @classmethod
    def load(cls, path, mmap: bool | None = None) -> "Database":
        """Read a database file. With ``mmap`` the per-frame arrays are read-only memory maps of the file
        (see :mod:`lmm.data.npz_mmap`): pages are read when first touched, so memory holds the frames a
        run uses, not the whole database. ``None`` (the default) maps large files only
        (:func:`lmm.data.npz_mmap.worth_mapping`) and reads small ones whole (read-only as well)."""
        path = Path(path)
        if mmap is None:
            mmap = worth_mapping(path)
        with archive.read(path, DatabaseError, "lmm-studio database cache",
                          map_arrays=MAPPED_ARRAYS if mmap else ()) as z:
            z.refuse_unknown(_ARCHIVE_ARRAYS)
            meta = z.metadata(MAX_METADATA_BYTES)
            if not isinstance(meta, dict) or meta.get("format_version") != DB_FORMAT_VERSION:
                version = meta.get("format_version") if isinstance(meta, dict) else None
                z.fail(f"database format {version}, expected {DB_FORMAT_VERSION}")
            db = cls(
                names=[str(s) for s in meta["names"]], parents=z["parents"].astype(np.int64),
                positions=z["positions"], rotations=z["rotations"], velocities=z["velocities"],
                angular_velocities=z["angular_velocities"], contacts=z["contacts"], toe_speeds=z["toe_speeds"],
                range_starts=z["range_starts"].astype(np.int64), range_stops=z["range_stops"].astype(np.int64),
                range_names=[str(s) for s in meta["range_names"]], range_mirrored=z["range_mirrored"],
                fps=float(meta["fps"]), bone_roles={str(r): str(b) for r, b in meta["bone_roles"]},
                mirror_map=z["mirror_map"].astype(np.int64), key=str(meta["key"]), name=str(meta["name"]),
                build_fingerprint=str(meta["build_fingerprint"]),
                range_tags=[tuple(t) for t in meta["range_tags"]], tag_names=[str(t) for t in meta["tag_names"]],
                frame_tags=np.asarray(z["frame_tags"], dtype=bool), feature_schema=list(meta["feature_schema"]))
        db.source_path = path
        return db


#: The per-frame arrays :meth:`Database.load` memory-maps (everything else is small and read).
MAPPED_ARRAYS = ("positions", "rotations", "velocities", "angular_velocities", "contacts", "toe_speeds",
                 "frame_tags")
#: Every array of a database file (names, tags, settings and keys are in its metadata).
_ARCHIVE_ARRAYS = MAPPED_ARRAYS + ("parents", "range_starts", "range_stops", "range_mirrored", "mirror_map")
#: Largest metadata record of a database file: range names and tags, about 100 bytes a range.
MAX_METADATA_BYTES = 64 * 1024 * 1024


# ---------------------------------------------------------------------------------------------
# building blocks (pure functions over arrays)
# ---------------------------------------------------------------------------------------------

def mirror_map(names: list[str], pairs) -> np.ndarray:
    """For each joint the index of its left/right counterpart (itself when it has none)."""
    index = {n: i for i, n in enumerate(names)}
    out = np.arange(len(names))
    for i, n in enumerate(names):
        for left, right in pairs:
            for a, b in ((left, right), (right, left)):
                if a in n:
                    j = index.get(n.replace(a, b))
                    if j is not None:
                        out[i] = j
                        break
            if out[i] != i:
                break
    return out


# local-space reflections S a skeleton's left/right offsets may follow (o[mirror] = S o), each with
# the quaternion of the proper rotation M S (M = diag(-1, 1, 1), the world mirror)
_OFFSET_REFLECTIONS = ((np.array([-1.0, 1.0, 1.0]), np.array([1.0, 0.0, 0.0, 0.0])),
                       (np.array([1.0, -1.0, 1.0]), np.array([0.0, 0.0, 0.0, 1.0])),
                       (np.array([1.0, 1.0, -1.0]), np.array([0.0, 0.0, 1.0, 0.0])))


def mirror_frame_rotation(offsets, parents, mirror_idx) -> np.ndarray:
    """The constant rotation C that keeps mirrored local frames those of the original skeleton.

    M R M alone turns every bone offset o into M o, a different skeleton (LAFAN1: legs point along -X),
    so inertializing or blending across mirrored/unmirrored frames would shrink bones through zero.
    With S the reflection relating left and right offsets (o[mirror] ~ S o), M R S = (M R M) (M S)
    gives back the original offsets, so C = M S.
    """
    child = np.asarray(parents) >= 0
    errors = [np.abs(offsets[mirror_idx][child] - s * offsets[child]).sum() for s, _ in _OFFSET_REFLECTIONS]
    return _OFFSET_REFLECTIONS[int(np.argmin(errors))][1]


def mirror_local(local_rot, local_pos, parents, mirror_idx, global_transforms=None):
    """Reflect a motion across the world YZ plane (negate X) and swap left/right joints.

    Bone offsets stay those of the original skeleton (see :func:`mirror_frame_rotation`).
    ``global_transforms``: ``forward_kinematics(local_rot, local_pos, parents)`` when the caller has it.
    """
    g_rot, g_pos = global_transforms or forward_kinematics(local_rot, local_pos, parents)
    g_pos = g_pos * np.array([-1.0, 1.0, 1.0])
    g_rot = g_rot * np.array([1.0, 1.0, -1.0, -1.0])  # M R M with M = diag(-1, 1, 1)
    g_rot = quat.mul(g_rot, mirror_frame_rotation(np.asarray(local_pos)[0], parents, mirror_idx))
    g_rot, g_pos = g_rot[..., mirror_idx, :], g_pos[..., mirror_idx, :]
    return global_to_local(g_rot, g_pos, parents)


def resampled_length(n: int, source_fps: float, target_fps: float, speed_scale: float = 1.0) -> int:
    """How many frames :func:`resample` makes of ``n`` (computed without making them)."""
    step = source_fps * speed_scale / target_fps
    if abs(step - 1.0) < 1e-12:
        return int(n)
    return max(0, int(np.ceil((n - 1 + 1e-9) / step)))


def resample(local_rot, local_pos, source_fps: float, target_fps: float, speed_scale: float = 1.0):
    """Cubic resampling of one contiguous range; ``speed_scale`` > 1 plays the motion faster."""
    n = local_rot.shape[0]
    step = source_fps * speed_scale / target_fps
    if abs(step - 1.0) < 1e-12:
        return local_rot.copy(), local_pos.copy()
    t = np.arange(0.0, n - 1 + 1e-9, step)
    rot = quat.normalize(catmull_rom(quat.unroll(local_rot, axis=0), t))
    pos = catmull_rom(local_pos, t)
    return rot, pos


def simulation_bone(global_rot, global_pos, spine: int, hips: int, hips_forward_axis, manifest: Manifest):
    """Smoothed ground projection of the spine (position) and of the hips' forward axis (facing)."""
    sim_pos = global_pos[:, spine] * np.array([1.0, 0.0, 1.0])
    sim_pos = savgol_smooth(sim_pos, manifest.simulation_position_window, manifest.simulation_order)
    sim_pos[:, 1] = 0.0
    forward = quat.mul_vec(global_rot[:, hips], np.asarray(hips_forward_axis, dtype=np.float64))
    forward = forward * np.array([1.0, 0.0, 1.0])
    forward /= np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), 1e-8)
    forward = savgol_smooth(forward, manifest.simulation_direction_window, manifest.simulation_order)
    forward[:, 1] = 0.0
    forward /= np.maximum(np.linalg.norm(forward, axis=-1, keepdims=True), 1e-8)
    angle = np.arctan2(forward[:, 0], forward[:, 2])
    sim_rot = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), angle)
    return sim_rot, sim_pos


def quat_central_difference(q: np.ndarray, dt: float) -> np.ndarray:
    """Angular velocity (rad/s, in the frame q is expressed in) by central differences along axis 0."""
    n = q.shape[0]
    out = np.zeros(q.shape[:-1] + (3,), dtype=np.float64)
    if n < 2:
        return out
    # frame i's difference reads frames i - 1 and i + 1 only: on long takes a block of frames at a time,
    # joint-major (the same operations, the same bits)
    if q.ndim == 3 and n > quat.FRAME_BLOCK:
        for s in quat.frame_blocks(n - 2):
            rows = quat.joint_major(q[2 + s.start:2 + s.stop], q.dtype)   # in q's own type, as in one go
            before = quat.joint_major(q[s], q.dtype)
            out[1 + s.start:1 + s.stop] = _angular_velocity_rows(rows, before, 2 * dt).transpose(2, 0, 1)
    elif n > 2:
        out[1:-1] = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(q[2:], q[:-2]))) / (2 * dt)
    out[0] = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(q[1], q[0]))) / dt
    out[-1] = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(q[-1], q[-2]))) / dt
    return out


def _angular_velocity_rows(a: np.ndarray, b: np.ndarray, dt: float, eps: float = 1e-8) -> np.ndarray:
    """``quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(a, b))) / dt`` on joint-major component rows
    (J, 4, B): the operations of those functions in their order (conj, product, abs_ twice, the norm's
    sum of squares, arctan2 of the clipped w, the small-angle choice), so the same bits. Returns (J, 3, B)."""
    bw, bx, by, bz = b.transpose(1, 0, 2)
    q = np.empty_like(a)
    quat.mul_rows(a.transpose(1, 0, 2), (bw, -bx, -by, -bz), q.transpose(1, 0, 2))
    w = q[:, 0]
    flip = w < 0.0                                    # abs_ (the second abs_ in log changes nothing)
    np.negative(q, out=q, where=flip[:, None, :])
    xyz = q[:, 1:]
    x, y, z = xyz.transpose(1, 0, 2)
    length = np.sqrt(x * x + y * y + z * z)
    small = length < eps
    safe = np.where(small, 1.0, length)
    halfangle = np.arctan2(length, np.clip(w, -1.0, 1.0))
    out = np.where(small[:, None, :], xyz, (halfangle / safe)[:, None, :] * xyz)
    out *= 2.0
    out /= dt
    return out


def foot_contacts(toe_global_pos: np.ndarray, dt: float, threshold: float, window: int):
    """Contact where the median-filtered toe speed is under the threshold. Returns (contacts, filtered speed)."""
    speed = np.linalg.norm(central_difference(toe_global_pos, dt), axis=-1)
    filtered = median_filter(speed, window)
    return filtered < threshold, filtered


# ---------------------------------------------------------------------------------------------
# the build
# ---------------------------------------------------------------------------------------------

def build_code_fingerprint() -> str:
    """Hash of the source of every module the build runs.

    A cache file is reused only when this matches, so a change to the build code can never serve a stale
    cache under an unchanged key (the key itself changes only with DB_FORMAT_VERSION, because networks
    trained on a database are tied to it: bump the version when a change alters the built data).
    """
    h = hashlib.sha256()
    data = Path(__file__).resolve().parent
    engine = data.parent
    for path in (data / "database.py", engine / "filters.py", engine / "quat.py", engine / "kinematics.py", data / "bvh.py", data / "manifest.py"):
        h.update(path.read_bytes())
    return h.hexdigest()


def database_range_tags(manifest: Manifest) -> list[tuple[str, ...]]:
    """The tags of every database range in build order (each range, then its mirror when mirrored)."""
    out = []
    for clip in manifest.clips:
        for k in range(len(clip.ranges or [None])):
            out += [clip.tags_of(k)] * (2 if manifest.mirror else 1)
    return out


def manifest_key(manifest: Manifest) -> str:
    """Hash of everything the build reads: file contents, settings and the build code's version.

    Tags are not part of it: they change no frame, so retagging keeps trained networks valid (a cached
    database whose tags differ from the manifest's is retagged on load)."""
    h = hashlib.sha256()
    h.update(f"lmm-db-v{DB_FORMAT_VERSION}".encode())
    h.update(json.dumps(manifest.settings(), sort_keys=True).encode())
    for ci, clip in enumerate(manifest.clips):
        try:
            h.update(_file_digest(clip.file).encode())
        except OSError as e:
            raise ManifestError(manifest.path, f"clips[{ci}].file",
                                f"cannot read {clip.file}: {e.strerror or type(e).__name__}") from None
    return h.hexdigest()


def cache_file_name(key: str) -> str:
    """The cache file of a database: its key only (hex digits), never text from the manifest."""
    if not key or any(c not in "0123456789abcdef" for c in key):
        raise ValueError(f"a database key is hex digits, got {key[:20]!r}")
    return f"db-{key[:32]}.npz"


def default_cache_dir() -> Path:
    env = os.environ.get("LMM_STUDIO_CACHE")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or (Path.home() / ".cache")
    return Path(base) / "lmm-studio"


#: Most worker processes a build uses (one take each at a time; a few hundred MB each at the peak).
MAX_BUILD_WORKERS = 4


@dataclass
class _Piece:
    """One finished database range (float32 as stored), made from one range of one take."""
    name: str
    mirrored: bool
    positions: np.ndarray
    rotations: np.ndarray
    velocities: np.ndarray
    angular_velocities: np.ndarray
    contacts: np.ndarray
    toe_speeds: np.ndarray


@dataclass
class _Take:
    """What one take adds to the database: its skeleton, its ranges' frame counts and its pieces."""
    names: list[str]
    parents: np.ndarray
    n_frames: int          # frames it adds (mirrored copies included)
    pieces: list[_Piece]


def _finish_piece(name: str, is_mirror: bool, rot, pos, parents, manifest: Manifest, names,
                  global_transforms=None) -> _Piece:
    """A resampled range -> the stored range: simulation bone, velocities, contacts (float32).
    ``global_transforms``: ``forward_kinematics(rot, pos, parents)`` when the caller has it."""
    hips, spine = names.index(manifest.bones["hips"]), names.index(manifest.bones["spine"])
    toes = [names.index(manifest.bones["left_toe"]), names.index(manifest.bones["right_toe"])]
    dt = 1.0 / manifest.target_fps
    g_rot, g_pos = global_transforms or forward_kinematics(rot, pos, parents)
    sim_rot, sim_pos = simulation_bone(g_rot, g_pos, spine, hips, manifest.hips_forward_axis, manifest)
    # re-parent every root of the file under the simulation bone
    rot = rot.copy()
    pos = pos.copy()
    for j in np.where(parents < 0)[0]:
        rot[:, j] = quat.inv_mul(sim_rot, rot[:, j])
        pos[:, j] = quat.inv_mul_vec(sim_rot, pos[:, j] - sim_pos)
    full_rot = quat.unroll(np.concatenate([sim_rot[:, None], rot], axis=1), axis=0)
    full_pos = np.concatenate([sim_pos[:, None], pos], axis=1)
    speeds = np.stack([foot_contacts(g_pos[:, t], dt, manifest.contact_speed_threshold_m_s,
                                     manifest.contact_median_window)[1] for t in toes], axis=-1).astype(np.float32)
    return _Piece(
        name=name, mirrored=is_mirror,
        positions=full_pos.astype(np.float32), rotations=full_rot.astype(np.float32),
        velocities=central_difference(full_pos, dt).astype(np.float32),
        angular_velocities=quat_central_difference(full_rot, dt).astype(np.float32),
        # threshold the stored float32 speeds so the invariant holds exactly on what is saved
        contacts=speeds < np.float32(manifest.contact_speed_threshold_m_s), toe_speeds=speeds)


def _build_take(manifest: Manifest, ci: int, skeleton=None, frames_before: int = 0) -> _Take:
    """Take ``ci`` of the manifest as database ranges, checked in the build's order: its file, its
    skeleton (against ``skeleton``, the first take's (names, parents), or the bone roles when None),
    then each range (bounds, length, the database frame limit counting ``frames_before``)."""
    mpath = manifest.path
    clip = manifest.clips[ci]
    copies = 2 if manifest.mirror else 1
    try:
        anim = bvh.load(clip.file)  # BVHError names the file and line
    except OSError as e:
        raise ManifestError(mpath, f"clips[{ci}].file",
                            f"cannot read {clip.file}: {e.strerror or type(e).__name__}") from None
    names, parents = list(anim.names), np.asarray(anim.parents, dtype=np.int64)
    if skeleton is None:
        for role, bone_name in manifest.bones.items():
            if bone_name not in names:
                raise ManifestError(mpath, f"bones.{role}",
                                    f"joint {bone_name!r} not in {clip.file.name} (joints: {', '.join(names)})")
    elif names != skeleton[0] or not np.array_equal(parents, skeleton[1]):
        raise ManifestError(mpath, f"clips[{ci}].file",
                            f"{clip.file.name} has a different skeleton from {manifest.clips[0].file.name}")
    mirror_idx = mirror_map(names, manifest.mirror_name_pairs)
    local_rot = anim.local_rotations()
    local_pos = anim.local_positions() * manifest.unit_scale
    source_fps = 1.0 / anim.frame_time
    if abs(source_fps - round(source_fps)) < 0.01:
        source_fps = float(round(source_fps))  # "Frame Time: 0.033333" means 30 fps, not 30.0003
    ranges = clip.ranges or [(0, anim.n_frames)]
    pieces = []
    total_frames = frames_before
    for ri, (start, stop) in enumerate(ranges):
        if stop > anim.n_frames:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]",
                                f"stop {stop} is past the last frame of {clip.file.name} ({anim.n_frames} frames)")
        if stop - start < MIN_RANGE_FRAMES:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]", "a range needs at least 4 frames")
        n_out = resampled_length(stop - start, source_fps, manifest.target_fps, manifest.speed_scale)
        if n_out < MIN_RANGE_FRAMES:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]",
                                f"{stop - start} frames at {source_fps:g} fps make {n_out} at target_fps "
                                f"{manifest.target_fps:g} (speed_scale {manifest.speed_scale:g}): a range "
                                f"needs at least {MIN_RANGE_FRAMES} frames")
        total_frames += n_out * copies
        if total_frames > MAX_DATABASE_FRAMES:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]",
                                f"the database would pass {MAX_DATABASE_FRAMES} frames here (at target_fps "
                                f"{manifest.target_fps:g}, speed_scale {manifest.speed_scale:g}"
                                f"{', mirrored' if manifest.mirror else ''}): use fewer or shorter ranges")
        rot, pos = resample(quat.unroll(local_rot[start:stop]), local_pos[start:stop], source_fps,
                            manifest.target_fps, manifest.speed_scale)
        base = f"{clip.file.name.split('.')[0]}[{start}:{stop}]"
        # the range's forward kinematics, once for the piece and its mirrored copy
        global_transforms = forward_kinematics(rot, pos, parents)
        pieces.append(_finish_piece(base, False, rot, pos, parents, manifest, names, global_transforms))
        if manifest.mirror:
            mrot, mpos = mirror_local(rot, pos, parents, mirror_idx, global_transforms)
            pieces.append(_finish_piece(base + " mirrored", True, quat.unroll(mrot), mpos, parents, manifest, names))
    return _Take(names, parents, total_frames - frames_before, pieces)


#: the arrays of a :class:`_Piece` (the rest are its name and mirror flag)
_PIECE_ARRAYS = ("positions", "rotations", "velocities", "angular_velocities", "contacts", "toe_speeds")


def _build_take_or_none(job) -> _Take | None:
    """A worker's job: the take, or None when it fails (the build then redoes it in order to raise the
    very error a one-process build raises). With a spill folder the pieces' arrays are written there as
    ``.npy`` files and the take comes back holding their paths (see :func:`_unspill`): a long take's
    arrays are tens of MB, and pickling them through the pool's pipe cost the parent process about 4 s
    of CPU for the 0.5 M-frame set, against a read of files the page cache still holds."""
    manifest, ci, spill = job
    try:
        take = _build_take(manifest, ci)
        if spill is not None:
            for k, piece in enumerate(take.pieces):
                for name in _PIECE_ARRAYS:
                    path = os.path.join(spill, f"{ci}-{k}-{name}.npy")
                    np.save(path, getattr(piece, name), allow_pickle=False)
                    setattr(piece, name, path)
        return take
    except Exception:
        return None


def _unspill(take: _Take | None) -> _Take | None:
    """A worker's take with its spilled arrays read back (memory maps of the files)."""
    if take is not None:
        for piece in take.pieces:
            for name in _PIECE_ARRAYS:
                value = getattr(piece, name)
                if isinstance(value, str):
                    setattr(piece, name, np.load(value, mmap_mode="r", allow_pickle=False))
    return take


def build_workers(manifest: Manifest) -> int:
    """Worker processes worth using for a build: one per core (at most :data:`MAX_BUILD_WORKERS`), none
    for one take."""
    n = min(MAX_BUILD_WORKERS, os.cpu_count() or 1, len(manifest.clips))
    return n if n > 1 else 0


def _takes(manifest: Manifest, workers: int, spill: str | None = None):
    """The takes in manifest order, each checked exactly as a one-process build checks it. With
    ``workers`` > 0 they are built in that many processes, ahead of the order (their arrays passed
    through files in the folder ``spill`` when given, see :func:`_build_take_or_none`); a take that
    failed there or breaks a cross-take rule is built again here, which raises."""
    skeleton, total = None, 0
    workers = min(workers, len(manifest.clips))
    if workers <= 1:
        for ci in range(len(manifest.clips)):
            take = _build_take(manifest, ci, skeleton, total)
            skeleton, total = skeleton or (take.names, take.parents), total + take.n_frames
            yield take
        return
    import multiprocessing

    # fork where there is one: no re-import of the caller's main module (spawn's) is needed
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    with multiprocessing.get_context(method).Pool(workers) as pool:
        jobs = [(manifest, ci, spill) for ci in range(len(manifest.clips))]
        for ci, take in enumerate(map(_unspill, pool.imap(_build_take_or_none, jobs))):
            if (take is None or total + take.n_frames > MAX_DATABASE_FRAMES
                    or (skeleton is not None and (take.names != skeleton[0]
                                                  or not np.array_equal(take.parents, skeleton[1])))):
                take = _build_take(manifest, ci, skeleton, total)  # raises the build's own error
            skeleton, total = skeleton or (take.names, take.parents), total + take.n_frames
            yield take


def build(manifest: Manifest, progress=None, workers: int = 0) -> Database:
    """Build the database from a parsed manifest. ``progress(done, total, label)`` is called per range.
    ``workers``: processes that build takes side by side (0: this process only; see :func:`build_workers`),
    for single-threaded callers such as ``lmm-studio build-db`` (forking a process that runs threads, a GUI,
    is not safe); the database is the same bit for bit either way."""
    total_ranges = sum(len(c.ranges) if c.ranges else 1 for c in manifest.clips) * (2 if manifest.mirror else 1)
    workers = min(workers, len(manifest.clips))
    # the workers' arrays come back through files here (removed once joined into the database's arrays)
    spill = (tempfile.TemporaryDirectory(prefix="lmm-build-", ignore_cleanup_errors=True) if workers > 1
             else contextlib.nullcontext(None))
    with spill as spill_dir:
        names = parents = None
        pieces: list[_Piece] = []
        for take in _takes(manifest, workers, spill_dir):
            names, parents = names or take.names, take.parents if parents is None else parents
            for piece in take.pieces:
                pieces.append(piece)
                if progress:
                    progress(len(pieces), total_ranges, piece.name)

        all_names = [SIMULATION_BONE] + names
        all_parents = np.concatenate([[-1], np.where(parents < 0, 0, parents + 1)]).astype(np.int64)
        lengths = np.array([p.positions.shape[0] for p in pieces], dtype=np.int64)
        stops = np.cumsum(lengths)
        mirror_full = np.concatenate([[0], mirror_map(names, manifest.mirror_name_pairs) + 1]).astype(np.int64)

        def joined(field_name):
            return np.concatenate([getattr(p, field_name) for p in pieces])

        db = Database(
            names=all_names, parents=all_parents,
            positions=joined("positions"), rotations=joined("rotations"), velocities=joined("velocities"),
            angular_velocities=joined("angular_velocities"), contacts=joined("contacts").astype(bool),
            toe_speeds=joined("toe_speeds"),
            range_starts=stops - lengths, range_stops=stops,
            range_names=[p.name for p in pieces], range_mirrored=np.array([p.mirrored for p in pieces], dtype=bool),
            fps=float(manifest.target_fps), bone_roles=dict(manifest.bones), mirror_map=mirror_full,
            key=manifest_key(manifest), name=manifest.name, build_fingerprint=build_code_fingerprint())
        pieces.clear()  # the files' maps closed before the folder goes
    db.set_tags(database_range_tags(manifest))
    set_feature_schema(db, manifest)
    return db


def set_feature_schema(db: Database, manifest: Manifest) -> None:
    """Give ``db`` the manifest's feature schema, checking that every channel's bone exists."""
    for i, ch in enumerate(manifest.features):
        if ch.get("bone") is not None:
            try:
                db.bone(ch["bone"])
            except KeyError:
                roles = ", ".join(sorted(db.bone_roles))
                raise ManifestError(manifest.features_file or manifest.path, f"features[{i}].bone",
                                    f"no joint or role named {ch['bone']!r} (roles: {roles})") from None
    db.feature_schema = [dict(ch) for ch in manifest.features]


@dataclass
class LoadInfo:
    path: Path | None     # the database file read or written; None when it could not be saved
    cached: bool
    seconds: float
    not_saved: str = ""   # why a built database could not be cached (a read-only cache folder...)


def load_or_build(manifest_path=None, cache_dir=None, progress=None, rebuild: bool = False,
                  out_path=None, workers: int = 0, before_save=None) -> tuple[Database, LoadInfo]:
    """The database for a manifest, from the cache when its key matches, else built (``workers``: see
    :func:`build`) and cached.

    With ``out_path`` the database is written there and a failure to write it is an ``OSError`` (the
    caller asked for that file); a cache that cannot be written is only reported in ``LoadInfo``.
    ``before_save(db, path)``, when given, is called after a build, before the file is written (the
    caller may start work that needs the database and the path, e.g. its derived arrays, meanwhile)."""
    t0 = time.perf_counter()
    manifest = load_manifest(manifest_path or DEFAULT_MANIFEST)
    key = manifest_key(manifest)
    path = Path(out_path) if out_path else Path(cache_dir or default_cache_dir()) / cache_file_name(key)
    if not rebuild and path.is_file():
        try:
            db = Database.load(path)
            if db.key == key and db.build_fingerprint == build_code_fingerprint():
                tags = database_range_tags(manifest)
                # retagged manifest or a new feature schema: same frames, so the cache is updated in place
                # (the key, and the networks trained on these frames, stay valid; networks trained on
                # another schema are refused by lmm.data.weights with what differs)
                if db.range_tags != tags or db.feature_schema != manifest.features:
                    db.set_tags(tags)
                    set_feature_schema(db, manifest)
                    try:
                        db.save(path)
                    except OSError:
                        pass
                return db, LoadInfo(path, True, time.perf_counter() - t0)
        except DatabaseError:
            pass  # stale or damaged cache: rebuild below
    db = build(manifest, progress=progress, workers=workers)
    if before_save is not None:
        before_save(db, path)
    if out_path:
        db.save(path)  # atomic: an OSError leaves no file behind, and the caller reports it
        db.source_path = path
        return db, LoadInfo(path, False, time.perf_counter() - t0)
    try:
        db.save(path)
    except OSError as e:  # a read-only or full cache location must not stop the tool
        return db, LoadInfo(None, False, time.perf_counter() - t0,
                            not_saved=f"cannot write the cache {path}: {e.strerror or type(e).__name__}")
    db.source_path = path  # its derived arrays are cached beside the file (lmm.data.derived)
    return db, LoadInfo(path, False, time.perf_counter() - t0)


def load_default(progress=None) -> Database:
    return load_or_build(progress=progress)[0]

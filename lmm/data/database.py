"""The motion database: every frame of every clip range, at 60 Hz, mirrored, with a simulation bone.

Bone 0 is always the simulation bone; its position/velocity are in world space and every other bone is
local to its parent (velocities and angular velocities in the parent's frame). This module holds the data
model and its file: an archive (:mod:`lmm.data.archive`) whose per-frame arrays are memory-mapped on load
(see :mod:`lmm.data.npz_mmap`). Where the data comes from: :mod:`lmm.data.build` (from a manifest, in the
reference pipeline's order, with the maths of :mod:`lmm.data.preparation`) and :mod:`lmm.data.cache`
(the cache file's key and name).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lmm.data import archive
from lmm.data.npz_mmap import worth_mapping
from lmm.errors import InputError
from lmm.kinematics import forward_kinematics, forward_kinematics_of, forward_kinematics_velocity

DB_FORMAT_VERSION = 5  # 5: mirrored clips keep the original bone offsets


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
        return forward_kinematics_of(self.rotations, self.positions, self.parents, bones,
                                     np.arange(self.n_frames)[frames], self.FK_CHUNK_FRAMES)

    def global_kinematics(self, frames=slice(None)):
        """Global rotations, positions, velocities and angular velocities (float64)."""
        return forward_kinematics_velocity(
            self.rotations[frames].astype(np.float64), self.positions[frames].astype(np.float64),
            self.velocities[frames].astype(np.float64), self.angular_velocities[frames].astype(np.float64),
            self.parents)

    # -- persistence -----------------------------------------------------------------------
    def to_archive(self) -> tuple[dict[str, np.ndarray], dict]:
        """The arrays and the metadata of the database's file (:mod:`lmm.data.archive`)."""
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
            "fps": float(self.fps), "bone_roles": dict(self.bone_roles),
            "key": self.key, "name": self.name, "build_fingerprint": self.build_fingerprint,
            "range_tags": [list(t) for t in self.range_tags], "tag_names": list(self.tag_names),
            "feature_schema": self.feature_schema,
        }
        return arrays, metadata

    def save(self, path) -> None:
        # atomic: a killed build never leaves a half-written cache; the metadata in the manifest's order
        archive.write(path, *self.to_archive(), sort_keys=False)

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
            try:
                db = cls._from_archive(z, meta)
            except DatabaseError:
                raise
            except (KeyError, TypeError, ValueError, AttributeError, IndexError) as e:
                z.fail(f"inconsistent database ({type(e).__name__}: {str(e)[:200]})")
            problem = inconsistency(db)
            if problem:
                z.fail(f"inconsistent database: {problem}")
        db.source_path = path
        return db

    @classmethod
    def _from_archive(cls, z, meta) -> "Database":
        return cls(
            names=[str(s) for s in meta["names"]], parents=z["parents"].astype(np.int64),
            positions=z["positions"], rotations=z["rotations"], velocities=z["velocities"],
            angular_velocities=z["angular_velocities"], contacts=z["contacts"], toe_speeds=z["toe_speeds"],
            range_starts=z["range_starts"].astype(np.int64), range_stops=z["range_stops"].astype(np.int64),
            range_names=[str(s) for s in meta["range_names"]], range_mirrored=z["range_mirrored"],
            fps=float(meta["fps"]), bone_roles={str(r): str(b) for r, b in meta["bone_roles"].items()},
            mirror_map=z["mirror_map"].astype(np.int64), key=str(meta["key"]), name=str(meta["name"]),
            build_fingerprint=str(meta["build_fingerprint"]),
            range_tags=[tuple(t) for t in meta["range_tags"]], tag_names=[str(t) for t in meta["tag_names"]],
            frame_tags=np.asarray(z["frame_tags"], dtype=bool), feature_schema=list(meta["feature_schema"]))


def inconsistency(db: Database) -> str | None:
    """What makes a loaded database unusable (shapes that disagree, ranges outside the frames, a parent
    after its child, bone roles naming no bone...), or None. Checked on every load, so a damaged or
    hand-made cache is rebuilt rather than failing later inside the runtime (12 such caches gave exit 70).
    Only shapes and the small arrays are read: the per-frame arrays stay unread memory maps."""
    n, j = db.positions.shape[:2] if db.positions.ndim == 3 else (-1, -1)
    shapes = {"positions": (db.positions, (n, j, 3)), "rotations": (db.rotations, (n, j, 4)),
              "velocities": (db.velocities, (n, j, 3)), "angular_velocities": (db.angular_velocities, (n, j, 3)),
              "contacts": (db.contacts, (n, 2)), "toe_speeds": (db.toe_speeds, (n, 2)), "parents": (db.parents, (j,)),
              "mirror_map": (db.mirror_map, (j,)), "frame_tags": (db.frame_tags, (n, len(db.tag_names)))}
    for name, (array, shape) in shapes.items():
        if array is None or tuple(array.shape) != shape:
            return f"{name} has shape {None if array is None else tuple(array.shape)}, expected {shape}"
    if n < 1 or j < 2 or len(db.names) != j:
        return f"{len(db.names)} bone names for {j} bones and {n} frames"
    if db.parents[0] != -1 or any(not 0 <= p < k for k, p in enumerate(db.parents.tolist()) if k > 0):
        return "a bone's parent is not an earlier bone"
    if db.mirror_map.min() < 0 or db.mirror_map.max() >= j:
        return "mirror_map names a bone that does not exist"
    r = len(db.range_starts)
    if r < 1 or len(db.range_stops) != r or len(db.range_names) != r or len(db.range_mirrored) != r \
            or (db.range_tags and len(db.range_tags) != r):
        return f"{r} ranges, but the range arrays disagree on their number"
    starts, stops = np.asarray(db.range_starts), np.asarray(db.range_stops)
    if starts.min() < 0 or stops.max() > n or (stops <= starts).any():
        return f"a range outside frames 0..{n} (or empty)"
    if not (np.isfinite(db.fps) and 1.0 <= db.fps <= 1000.0):
        return f"fps {db.fps}"
    missing = sorted(b for b in db.bone_roles.values() if b not in db.names)
    if missing:
        return f"bone roles name {missing[0]!r}, which is not a bone"
    return None


#: The per-frame arrays :meth:`Database.load` memory-maps (everything else is small and read).
MAPPED_ARRAYS = ("positions", "rotations", "velocities", "angular_velocities", "contacts", "toe_speeds",
                 "frame_tags")
#: Every array of a database file (names, tags, settings and keys are in its metadata).
_ARCHIVE_ARRAYS = MAPPED_ARRAYS + ("parents", "range_starts", "range_stops", "range_mirrored", "mirror_map")
#: Largest metadata record of a database file: range names and tags, about 100 bytes a range.
MAX_METADATA_BYTES = 64 * 1024 * 1024

"""Crash-safe streaming of a running character to BVH.

The recording uses the database skeleton without its simulation bone: ``Hips`` is the BVH root and
carries the world translation (``Xposition Yposition Zposition``) and world rotation, every other joint
its local rotation (``Zrotation Yrotation Xrotation``), bone offsets from the database. Units are
centimetres, as in the LAFAN1 source files, so a recording opens like the data it came from; the
joints' world positions equal the pose's global positions (x 100) to well under 0.1 mm. The simulation
bone is left out because it is a smoothed ground projection, not a joint of the captured skeleton.

Crash safety (the rules of :class:`lmm.data.stream.StreamFile`): frames are buffered in memory and
appended at least every ``flush_interval_s`` seconds of wall time, whole frames only; after appending,
the fixed-width ``Frames:`` count in the header is rewritten in place and the file is fsynced. The file
appears under its name only with its first frames (header and frames written to a hidden temporary
file and renamed), so a recording with no frame leaves no file, and a killed process leaves either no
file or a complete, valid BVH with at least one frame (which Blender's importer needs) that lacks at
most the frames of the last ``flush_interval_s`` (0.5 s by default). A full disk cuts the file back to
its last complete flush and raises :class:`lmm.data.stream.StreamWriteError`. The one window where the
count is lower than the frames present is between the append and the count rewrite, two consecutive
system calls; :func:`repair` fixes such a file.
"""
from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from lmm import quat
from lmm.data import bvh
from lmm.data.stream import BufferedStreamWriter, StreamFile, repair_count

ROOT_CHANNELS = ("Xposition", "Yposition", "Zposition", "Zrotation", "Yrotation", "Xrotation")
JOINT_CHANNELS = ("Zrotation", "Yrotation", "Xrotation")
EULER_ORDER = "zyx"


def recording_skeleton(db, scale: float = 100.0) -> dict:
    """The BVH skeleton of a database (bone 0 dropped, the first real bone as root), as a mapping that
    :func:`lmm.data.bvh.header_text` accepts."""
    names = list(db.names[1:])
    parents = np.asarray(db.parents[1:], dtype=np.int64) - 1
    parents[parents < 0] = -1
    offsets = db.positions[0, 1:].astype(np.float64) * scale
    offsets[parents < 0] = 0.0  # the root's place comes from its position channels
    channels = [ROOT_CHANNELS if p < 0 else JOINT_CHANNELS for p in parents]
    has_child = np.zeros(len(names), dtype=bool)
    has_child[parents[parents >= 0]] = True
    end_sites = {int(j): np.zeros(3) for j in np.flatnonzero(~has_child)}
    return {"names": names, "parents": parents, "offsets": offsets, "channels": channels, "end_sites": end_sites}


def pose_to_motion_row(local_rotations, global_positions, global_rotations, scale: float = 100.0) -> np.ndarray:
    """One BVH frame row from a pose (database skeleton, bone 0 = simulation bone)."""
    rot = np.asarray(local_rotations, dtype=np.float64).copy()
    rot[1] = np.asarray(global_rotations[1], dtype=np.float64)  # the root's rotation is its world rotation
    euler = np.degrees(quat.to_euler(quat.normalize(rot[1:]), EULER_ORDER))   # (J - 1, 3)
    root_pos = np.asarray(global_positions[1], dtype=np.float64) * scale
    return np.concatenate([root_pos, euler.ravel()])


def _count_field(n: int) -> bytes:
    return bvh.frames_field(n).encode("ascii")


class BVHRecorder(BufferedStreamWriter):
    """Stream poses to ``path`` as BVH (see the module doc). Use as a context manager or call close().

    ``overwrite=False`` refuses an existing file at the start (the studio's recordings). Raises
    ``OSError`` at once when the folder cannot be written.
    """

    def __init__(self, path, db, fps: float = 60.0, flush_interval_s: float = 0.5, precision: int = 6,
                 scale: float = 100.0, clock=time.monotonic, overwrite: bool = True):
        self.path = Path(path)
        self.scale = scale
        self.precision = precision
        self.flush_interval_s = flush_interval_s
        self._clock = clock
        self.skeleton = recording_skeleton(db, scale)
        header = bvh.header_text(self.skeleton, n_frames=0, frame_time=1.0 / fps, precision=precision)
        self._stream = StreamFile(self.path, header.encode("utf-8"), overwrite=overwrite, unit="frames",
                                  count_offset=bvh.frames_field_offset(header), format_count=_count_field,
                                  page_lines=True)
        self.frames = 0           # written or pending
        self._pending: list[np.ndarray] = []
        self._last_flush = self._clock()

    @property
    def frames_written(self) -> int:
        """Frames in the file on disk (0 while no file exists)."""
        return self._stream.records

    def write(self, pose) -> None:
        """Append one pose (:class:`lmm.controller.Pose`); flushes when the interval has passed."""
        self.write_row(pose_to_motion_row(pose.local_rotations, pose.global_positions, pose.global_rotations,
                                          self.scale))

    def write_row(self, row: np.ndarray) -> None:
        if self._stream.closed:
            raise ValueError(f"{self.path}: the recorder is closed")
        self._pending.append(np.asarray(row, dtype=np.float64))
        self.frames += 1
        self._flush_if_due()

    def _encode(self, pending: list) -> bytes:
        """The pending frames as BVH motion lines (the stream rewrites the frame count and fsyncs)."""
        return bvh.format_frames(np.stack(pending), self.precision).encode("utf-8")

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass


def repair(path) -> int:
    """Make a recording's ``Frames:`` count match its complete frame lines (dropping a partial last
    line): for a file whose writer was killed between appending frames and rewriting the count.
    Returns the frame count."""
    path = Path(path)
    with open(path, "rb") as f:
        head = f.read(1 << 20)
    end = head.find(b"\nFrame Time:")
    if end < 0:
        raise ValueError(f"{path}: no 'Frame Time:' line in the first MiB: not a recording")
    header_size = head.index(b"\n", end + 1) + 1
    offset = bvh.frames_field_offset(head[:header_size].decode("utf-8"))
    return repair_count(path, offset, _count_field, header_size)

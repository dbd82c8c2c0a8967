"""Crash-safe streaming of a running character to BVH.

The recording uses the database skeleton without its simulation bone: ``Hips`` is the BVH root and
carries the world translation (``Xposition Yposition Zposition``) and world rotation, every other joint
its local rotation (``Zrotation Yrotation Xrotation``), bone offsets from the database. Units are
centimetres, as in the LAFAN1 source files, so a recording opens like the data it came from; the
joints' world positions equal the pose's global positions (x 100) to well under 0.1 mm. The simulation
bone is left out because it is a smoothed ground projection, not a joint of the captured skeleton.

Crash safety: frames are buffered in memory and appended at least every ``flush_interval_s`` seconds of
wall time; after appending, the fixed-width ``Frames:`` count in the header is rewritten in place and
the file is fsynced. So after every flush the file on disk is a complete, valid BVH, and a killed
process loses at most the frames of the last ``flush_interval_s`` (0.5 s by default). The only window
where the file is not valid is between the append and the count rewrite, two consecutive system calls.
"""
from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from lmm import quat
from lmm.data import bvh

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


class BVHRecorder:
    """Stream poses to ``path`` as BVH (see the module doc). Use as a context manager or call close()."""

    def __init__(self, path, db, fps: float = 60.0, flush_interval_s: float = 0.5, precision: int = 6,
                 scale: float = 100.0, clock=time.monotonic):
        self.path = Path(path)
        self.scale = scale
        self.precision = precision
        self.flush_interval_s = flush_interval_s
        self._clock = clock
        self.skeleton = recording_skeleton(db, scale)
        header = bvh.header_text(self.skeleton, n_frames=0, frame_time=1.0 / fps, precision=precision)
        self._count_offset = bvh.frames_field_offset(header)
        self._fd = os.open(self.path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
        self._write_all(header.encode("utf-8"))
        os.fsync(self._fd)
        self.frames_written = 0   # on disk
        self.frames = 0           # written or pending
        self._pending: list[np.ndarray] = []
        self._last_flush = self._clock()

    def write(self, pose) -> None:
        """Append one pose (:class:`lmm.controller.Pose`); flushes when the interval has passed."""
        self.write_row(pose_to_motion_row(pose.local_rotations, pose.global_positions, pose.global_rotations,
                                          self.scale))

    def write_row(self, row: np.ndarray) -> None:
        if self._fd is None:
            raise ValueError("the recorder is closed")
        self._pending.append(np.asarray(row, dtype=np.float64))
        self.frames += 1
        if self._clock() - self._last_flush >= self.flush_interval_s:
            self.flush()

    def flush(self) -> None:
        """Append the pending frames, rewrite the frame count, fsync: a valid BVH on disk."""
        if self._fd is None:
            return
        if self._pending:
            text = bvh.format_frames(np.stack(self._pending), self.precision)
            self._write_all(text.encode("utf-8"))
            self.frames_written += len(self._pending)
            self._pending.clear()
            os.pwrite(self._fd, bvh.frames_field(self.frames_written).encode("ascii"), self._count_offset)
            os.fsync(self._fd)
        self._last_flush = self._clock()

    def close(self) -> None:
        if self._fd is not None:
            self.flush()
            os.close(self._fd)
            self._fd = None

    def _write_all(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            n = os.write(self._fd, view)
            view = view[n:]

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def __del__(self):
        try:
            self.close()
        except Exception:
            pass

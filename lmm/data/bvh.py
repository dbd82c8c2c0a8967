"""Reading and writing BVH (Biovision Hierarchy) motion files.

The reader accepts any hierarchy (several ROOTs included), any channel order,
any subset of the six standard channel names on any joint (position channels on
a non-root joint replace that joint's offset), End Sites, LF / CRLF / CR line
endings, tabs or spaces, and gzip-compressed files (detected by their magic
bytes). Keywords are matched with their standard spelling and case:
``HIERARCHY ROOT JOINT End Site { } OFFSET CHANNELS MOTION Frames: Frame Time:``.
Channel names are matched case-insensitively and kept exactly as written.

Speed: the header is parsed line by line (it is short); the motion block is
parsed by one vectorised ``numpy.loadtxt`` call and validated by shape and
finiteness. Only when that fails does a slow line-by-line pass run, whose only
job is to find the first bad line for the error message. Nothing is allocated
from the declared ``Frames:`` count.

Limits (checked before the work, so a hostile file costs bounded time and memory): the text is
at most :data:`MAX_TEXT_BYTES` (a gzip stream is inflated incrementally and abandoned past it), a
header line at most :data:`MAX_HEADER_LINE_CHARS`, at most :data:`MAX_JOINTS` joints,
:data:`MAX_FRAMES` frames, :data:`MAX_VALUES` values and :data:`MAX_JOINT_FRAMES` frames x joints, and the motion block no longer than its
declared frames of values can be (:data:`MAX_VALUE_CHARS` per value). Accepted values: a
``Frame Time`` from :data:`MIN_FRAME_TIME` to :data:`MAX_FRAME_TIME` seconds, every OFFSET and frame
value finite with magnitude at most :data:`MAX_ABS_VALUE`.

Every problem in a file raises :class:`BVHError`, which names the file, the
1-based line and what was expected; ``str(e) == f"{path}:{line}: {message}"``
(missing parts left out). A file that cannot be opened raises the usual
``OSError`` (``FileNotFoundError``...).

Streaming (crash-safe recorders): :func:`header_text` returns everything up to
and including the ``Frame Time:`` line, :func:`format_frames` formats frame
rows. The ``Frames:`` line is always written as ``"Frames: "`` followed by the
count left-justified and padded with spaces to :data:`FRAMES_FIELD_WIDTH`
characters (``frames_field(n)``), which is valid BVH. A recorder can therefore
append frames to the file and rewrite the count in place: seek to
``frames_field_offset(header)`` (a byte offset into the UTF-8 encoded header)
and write ``frames_field(n).encode()``; the file size of the header never
changes.
"""
from __future__ import annotations

import array
import dataclasses
import gzip
import io
import math
import os
import warnings
import zlib
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from lmm import kinematics, quat
from lmm.data.atomic import write_bytes_atomic
from lmm.data.reading import ascii_float, ascii_int, open_regular
from lmm.errors import InputError

__all__ = [
    "BVHError", "Animation", "load", "loads", "save", "dumps",
    "header_text", "format_frames", "frames_field", "frames_field_offset",
    "FRAMES_FIELD_WIDTH", "CHANNEL_NAMES", "MAX_TEXT_BYTES", "MAX_HEADER_LINE_CHARS", "MAX_JOINTS",
    "MAX_FRAMES", "MAX_VALUES", "MAX_JOINT_FRAMES", "MAX_VALUE_CHARS", "MIN_FRAME_TIME", "MAX_FRAME_TIME", "MAX_ABS_VALUE",
]

#: The six standard channel names.
CHANNEL_NAMES = ("Xposition", "Yposition", "Zposition", "Xrotation", "Yrotation", "Zrotation")
#: lower-case name -> (is_rotation, axis index 0..2)
_CHANNEL_INFO = {name.lower(): (name.endswith("rotation"), "xyz".index(name[0].lower()))
                 for name in CHANNEL_NAMES}
_POSITION_CHANNELS = ("Xposition", "Yposition", "Zposition")

#: Width of the padded count field on the ``Frames:`` line written by this module.
FRAMES_FIELD_WIDTH = 10
_FRAMES_PREFIX = "Frames: "

_GZIP_MAGIC = b"\x1f\x8b"

# --------------------------------------------------------------------------------------
# what the reader accepts: each limit is what the rest of the program can actually use
# --------------------------------------------------------------------------------------

#: Largest BVH text, after gzip. Parsing costs about 3x the text in memory (the text, its motion
#: block as bytes, the values), so 128 MiB stays well under 1 GB; it is 40x the largest shipped take
#: (3.2 MB) and holds about 190,000 frames of a 69-channel skeleton (1.7 hours at 30 fps).
MAX_TEXT_BYTES = 128 * 2**20
#: Longest header line (HIERARCHY, ROOT/JOINT name, OFFSET, CHANNELS, Frames:): real ones are under
#: 100 characters; a line is split into words, so its length bounds that work.
MAX_HEADER_LINE_CHARS = 4096
#: Most joints: full-body skeletons with fingers and a face rig have a few hundred.
MAX_JOINTS = 1000
#: Most frames: 11.5 hours at 120 fps; more cannot fit in MAX_TEXT_BYTES with even one channel each.
MAX_FRAMES = 5_000_000
#: Most values (frames x channels): 256 MB as float64, the motion array itself; the database and the
#: viewer keep several arrays of that size per take.
MAX_VALUES = 32 * 2**20
#: Most joint-frames (frames x joints, joints without channels included): the viewer, the checks and
#: the database pose every joint of every frame in float64, about 230 bytes a joint-frame at the peak
#: (measured: 3.46 million take 790 MB), so 3 million keeps loading and posing a take under 700 MB.
#: A shipped take has 0.18 million; a 23-joint skeleton may have 130,000 frames (72 min at 30 fps).
MAX_JOINT_FRAMES = 3_000_000
#: Longest text of one frame value with its separator: a float64 written with all 17 significant
#: digits, sign and exponent takes 24. The motion block may be at most this per value (plus a line
#: end per frame and 64 KiB of blank space), which bounds any padding and the length of a frame line.
MAX_VALUE_CHARS = 32
#: Accepted ``Frame Time`` (seconds): 10 kHz capture to 1 frame per second. The database resamples
#: a take by source_fps / target_fps (target 10..240 fps); slower than 1 fps is not an animation and
#: rounds to 0 fps, faster than 10 kHz leaves a few frames per range after resampling.
MIN_FRAME_TIME = 1e-4
MAX_FRAME_TIME = 1.0
#: Largest magnitude of an OFFSET or frame value: 10 km in centimetres (1 km in millimetres), or
#: 2,778 turns in degrees. Beyond it float32 (the database, the GPU) keeps less than 1 mm of a
#: position in metres, and velocities from differences of such values lose their meaning.
MAX_ABS_VALUE = 1e6
_BLANK_SLACK_CHARS = 65536


# --------------------------------------------------------------------------------------
# errors
# --------------------------------------------------------------------------------------

class BVHError(InputError):
    """A malformed BVH file. ``path`` (str or None), ``line`` (1-based int or None), ``message``."""

    def __init__(self, message: str, path: str | os.PathLike | None = None, line: int | None = None):
        super().__init__(message, path, line)
        self.message = str(message)
        self.path = None if path is None else os.fspath(path)
        self.line = None if line is None else int(line)

    def __str__(self) -> str:
        parts = [str(p) for p in (self.path, self.line) if p is not None]
        if not parts:
            return self.message
        return ":".join(parts) + ": " + self.message


def _show(tokens: list[str], limit: int = 40) -> str:
    """A short quoted rendering of a line's tokens for error messages."""
    s = " ".join(tokens)
    if len(s) > limit:
        s = s[:limit] + "..."
    return repr(s)


# --------------------------------------------------------------------------------------
# the animation container
# --------------------------------------------------------------------------------------

@dataclass(eq=False)
class Animation:
    """A skeleton and its raw channel values, exactly as stored in a BVH file.

    ``motion[:, channel_columns(j)]`` are the values of joint ``j``'s channels, in
    the order of ``channels[j]``. Rotations are in degrees, positions in file units.
    """

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    channels: list[tuple[str, ...]]
    motion: np.ndarray
    frame_time: float
    end_sites: dict[int, np.ndarray] = field(default_factory=dict)
    path: str | None = None

    def __post_init__(self):
        self.names = [str(n) for n in self.names]
        J = len(self.names)
        self.parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        self.offsets = np.asarray(self.offsets, dtype=np.float64).reshape(-1, 3) if J else np.zeros((0, 3))
        self.channels = [tuple(str(c) for c in ch) for ch in self.channels]
        self.frame_time = float(self.frame_time)
        self.end_sites = {int(k): np.asarray(v, dtype=np.float64).reshape(3)
                          for k, v in (self.end_sites or {}).items()}
        if self.path is not None:
            self.path = os.fspath(self.path)
        if self.parents.shape != (J,) or self.offsets.shape != (J, 3) or len(self.channels) != J:
            raise ValueError(f"names, parents, offsets and channels disagree on the joint count "
                             f"({J}, {self.parents.shape}, {self.offsets.shape}, {len(self.channels)})")
        for j, p in enumerate(self.parents):
            if not -1 <= p < j:
                raise ValueError(f"parents[{j}] = {p}: every parent must come before its child (or be -1)")
        for j, ch in enumerate(self.channels):
            low = [c.lower() for c in ch]
            if any(c not in _CHANNEL_INFO for c in low) or len(set(low)) != len(low):
                raise ValueError(f"joint {self.names[j]!r}: bad channel list {ch}")
        for k in self.end_sites:
            if not 0 <= k < J:
                raise ValueError(f"end site on joint {k}, which does not exist")
        C = sum(len(ch) for ch in self.channels)
        motion = np.asarray(self.motion, dtype=np.float64)
        if motion.ndim == 1 and C > 0 and motion.size % C == 0:
            motion = motion.reshape(-1, C)
        if motion.ndim != 2 or motion.shape[1] != C:
            raise ValueError(f"motion has shape {motion.shape}, expected (frames, {C})")
        self.motion = motion

    # --- sizes ----------------------------------------------------------------------
    @property
    def n_frames(self) -> int:
        return int(self.motion.shape[0])

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def n_channels(self) -> int:
        return int(self.motion.shape[1])

    @property
    def fps(self) -> float:
        return 1.0 / self.frame_time

    # --- channel access ---------------------------------------------------------------
    def _column_starts(self) -> np.ndarray:
        counts = np.fromiter((len(c) for c in self.channels), dtype=np.int64, count=len(self.channels))
        return np.concatenate([[0], np.cumsum(counts)])

    def channel_columns(self, j: int) -> list[int]:
        """The motion columns holding joint ``j``'s channels, in channel order."""
        j = int(j)
        if j < 0:
            j += self.n_joints
        start = int(self._column_starts()[j])
        return list(range(start, start + len(self.channels[j])))

    def local_positions(self) -> np.ndarray:
        """(F, J, 3) local translations: the offsets, with any position channel's value
        replacing the matching offset component (for any joint, not only roots)."""
        F = self.n_frames
        pos = np.repeat(self.offsets[None], F, axis=0)
        jj, aa, cc = [], [], []
        col = 0
        for j, chans in enumerate(self.channels):
            for c in chans:
                is_rot, axis = _CHANNEL_INFO[c.lower()]
                if not is_rot:
                    jj.append(j)
                    aa.append(axis)
                    cc.append(col)
                col += 1
        if cc:
            pos[:, jj, aa] = self.motion[:, cc]
        return pos

    def local_rotations(self) -> np.ndarray:
        """(F, J, 4) local rotations (w, x, y, z).

        The rotation channels of a joint compose in the order they are written:
        ``Zrotation Yrotation Xrotation`` means R = Rz Ry Rx. Joints with fewer than
        three rotation channels use the ones they have; no rotation channel means identity.
        """
        F, J = self.n_frames, self.n_joints
        rot = np.zeros((F, J, 4))
        rot[..., 0] = 1.0
        groups: dict[tuple[str, int], tuple[list[int], list[list[int]]]] = {}
        col = 0
        for j, chans in enumerate(self.channels):
            axes, cols = [], []
            for c in chans:
                is_rot, axis = _CHANNEL_INFO[c.lower()]
                if is_rot:
                    axes.append("xyz"[axis])
                    cols.append(col)
                col += 1
            if axes:
                order = "".join(axes) + "".join(a for a in "xyz" if a not in axes)
                js, cs = groups.setdefault((order, len(axes)), ([], []))
                js.append(j)
                cs.append(cols)
        for (order, n), (js, cs) in groups.items():
            angles = np.zeros((F, len(js), 3))
            angles[:, :, :n] = np.radians(self.motion[:, np.asarray(cs, dtype=np.int64)])
            rot[:, js] = quat.from_euler(angles, order)
        return rot

    def global_transforms(self) -> tuple[np.ndarray, np.ndarray]:
        """World rotations (F, J, 4) and positions (F, J, 3), in file units."""
        return kinematics.forward_kinematics(self.local_rotations(), self.local_positions(), self.parents)

    def global_positions(self) -> np.ndarray:
        """(F, J, 3) world positions of the joints, in file units."""
        return self.global_transforms()[1]

    # --- construction ----------------------------------------------------------------
    @classmethod
    def from_local(cls, names, parents, offsets, local_rotations, local_positions, frame_time, *,
                   rotation_order="zyx", position_joints=(0,), end_sites=None) -> "Animation":
        """Build an animation from local rotations (F, J, 4) and positions (F, J, 3).

        Joints in ``position_joints`` get ``Xposition Yposition Zposition`` channels
        (values from ``local_positions``) followed by rotation channels; the others get
        rotation channels only (their ``local_positions`` are ignored; ``offsets`` are used).
        ``rotation_order`` is one order for every joint (e.g. ``'zyx'`` writes
        ``Zrotation Yrotation Xrotation``) or a sequence of one order per joint, where an
        empty string gives the joint no rotation channels.
        """
        names = [str(n) for n in names]
        J = len(names)
        local_rotations = quat.normalize(np.asarray(local_rotations, dtype=np.float64))
        if local_rotations.ndim == 2:
            local_rotations = local_rotations[None]
        if local_rotations.shape[1:] != (J, 4):
            raise ValueError(f"local_rotations has shape {local_rotations.shape}, expected (F, {J}, 4)")
        F = local_rotations.shape[0]
        local_positions = np.broadcast_to(np.asarray(local_positions, dtype=np.float64), (F, J, 3))
        if isinstance(rotation_order, str):
            orders = [rotation_order.lower()] * J
        else:
            orders = [str(o).lower() for o in rotation_order]
            if len(orders) != J:
                raise ValueError(f"rotation_order has {len(orders)} entries for {J} joints")
        for o in orders:
            if o and sorted(o) != ["x", "y", "z"]:
                raise ValueError(f"bad rotation order {o!r}: expected a permutation of 'xyz' or ''")
        pos_set = set()
        for j in position_joints:
            j = int(j)
            if not -J <= j < J:
                raise ValueError(f"position joint {j} out of range")
            pos_set.add(j % J)
        # Euler angles per order, vectorised over the joints sharing it
        euler: dict[int, np.ndarray] = {}
        for o in set(orders):
            if not o:
                continue
            js = [j for j in range(J) if orders[j] == o]
            angles = np.degrees(quat.to_euler(local_rotations[:, js], o))
            for k, j in enumerate(js):
                euler[j] = angles[:, k]
        channels, blocks = [], []
        for j in range(J):
            chans: tuple[str, ...] = ()
            if j in pos_set:
                chans += _POSITION_CHANNELS
                blocks.append(local_positions[:, j])
            if orders[j]:
                chans += tuple(f"{a.upper()}rotation" for a in orders[j])
                blocks.append(euler[j])
            channels.append(chans)
        motion = np.concatenate(blocks, axis=1) if blocks else np.zeros((F, 0))
        return cls(names=names, parents=parents, offsets=offsets, channels=channels, motion=motion,
                   frame_time=frame_time, end_sites=dict(end_sites or {}))

    def slice(self, start, stop) -> "Animation":
        """The frames ``start:stop`` (Python slice semantics) as a new animation."""
        return dataclasses.replace(
            self, names=list(self.names), parents=self.parents.copy(), offsets=self.offsets.copy(),
            channels=list(self.channels), motion=self.motion[start:stop].copy(),
            end_sites={k: v.copy() for k, v in self.end_sites.items()})


# --------------------------------------------------------------------------------------
# reading
# --------------------------------------------------------------------------------------

class _Parser:
    """Line-oriented parser over the decoded text; lines are separated by '\\n'."""

    def __init__(self, text: str, path: str | None):
        self.text = text
        self.n = len(text)
        self.path = path
        self.pos = 0
        self.lineno = 0
        self.names: list[str] = []
        self.name_set: set[str] = set()
        self.parents: list[int] = []
        self.offsets: list[list[float]] = []
        self.channels: list[tuple[str, ...]] = []
        self.open_lines: list[int] = []
        self.end_sites: dict[int, np.ndarray] = {}
        self.max_line_chars = MAX_HEADER_LINE_CHARS

    def error(self, line: int | None, message: str) -> BVHError:
        return BVHError(message, self.path, line)

    def next_line(self) -> tuple[int, list[str]] | None:
        """The next non-blank line as (line number, tokens), or None at end of file."""
        text = self.text
        while self.pos < self.n:
            end = text.find("\n", self.pos)
            if end < 0:
                end = self.n
            if end - self.pos > self.max_line_chars:
                self.lineno += 1
                raise self.error(self.lineno, f"line of {end - self.pos} characters: expected at most "
                                              f"{self.max_line_chars} here")
            line = text[self.pos:end]
            self.pos = end + 1
            self.lineno += 1
            tokens = line.split()
            if tokens:
                return self.lineno, tokens
        return None

    def expect_line(self, what: str) -> tuple[int, list[str]]:
        item = self.next_line()
        if item is None:
            raise self.error(max(self.lineno, 1), f"unexpected end of file: expected {what}")
        return item

    # --- header ----------------------------------------------------------------------
    def parse(self) -> Animation:
        if not self.text or self.text.isspace():
            raise self.error(1, "empty file: expected HIERARCHY")
        ln, toks = self.expect_line("HIERARCHY")
        if toks != ["HIERARCHY"]:  # the words of a file that is no BVH are not echoed (it may be any file)
            raise self.error(ln, "expected HIERARCHY as the first line: not a BVH file")
        while True:
            item = self.next_line()
            if item is None:
                what = "ROOT" if not self.names else "ROOT or MOTION"
                raise self.error(max(self.lineno, 1), f"unexpected end of file: expected {what}")
            ln, toks = item
            if toks[0] == "ROOT":
                self.parse_root(ln, toks)
            elif toks == ["MOTION"] and self.names:
                break
            else:
                what = "ROOT" if not self.names else "ROOT or MOTION"
                raise self.error(ln, f"expected {what}, found {_show(toks)}")
        n_frames, frames_line = self.parse_frames()
        frame_time = self.parse_frame_time()
        n_channels = sum(len(c) for c in self.channels)
        self.check_motion_size(n_frames, n_channels, frames_line)
        motion = self.parse_motion(n_frames, n_channels, frames_line)
        return Animation(names=self.names, parents=np.asarray(self.parents, dtype=np.int64),
                         offsets=np.asarray(self.offsets, dtype=np.float64).reshape(-1, 3),
                         channels=self.channels, motion=motion, frame_time=frame_time,
                         end_sites=self.end_sites, path=self.path)

    def parse_root(self, ln: int, toks: list[str]) -> None:
        stack = [self.begin_joint(ln, toks, -1)]
        while stack:
            j = stack[-1]
            ln, toks = self.expect_line(f"'}}' closing {self.kind(j)} {self.names[j]!r} "
                                        f"(opened on line {self.open_lines[j]})")
            kw = toks[0]
            if kw == "JOINT":
                stack.append(self.begin_joint(ln, toks, j))
            elif kw == "End":
                self.end_site(ln, toks, j)
            elif toks == ["}"]:
                stack.pop()
            else:
                raise self.error(ln, f"expected JOINT, End Site or '}}' in {self.kind(j)} "
                                     f"{self.names[j]!r}, found {_show(toks)}")

    def kind(self, j: int) -> str:
        return "ROOT" if self.parents[j] < 0 else "JOINT"

    def open_brace(self, ln: int, toks: list[str], what: str) -> list[str]:
        """Strip a trailing '{' from a block-opening line, or read the '{' line after it."""
        rest = toks[1:]
        if rest and rest[-1] == "{":
            return rest[:-1]
        bl, btoks = self.expect_line(f"'{{' after {what}")
        if btoks != ["{"]:
            raise self.error(bl, f"expected '{{' after {what} on line {ln}, found {_show(btoks)}")
        return rest

    def begin_joint(self, ln: int, toks: list[str], parent: int) -> int:
        kw = toks[0]
        rest = toks[1:]
        if rest and rest[-1] == "{":
            rest = rest[:-1]
        if not rest or any(("{" in t or "}" in t) for t in rest):
            raise self.error(ln, f"expected a joint name after {kw}, found {_show(toks)}")
        name = " ".join(rest)
        if name in self.name_set:
            raise self.error(ln, f"duplicate joint name {name!r}: expected unique joint names")
        self.open_brace(ln, toks, f"{kw} {name}")
        offset = self.parse_offset(f"{kw} {name!r}")
        chans = self.parse_channels(f"{kw} {name!r}")
        j = len(self.names)
        if j >= MAX_JOINTS:
            raise self.error(ln, f"more than {MAX_JOINTS} joints: expected at most {MAX_JOINTS}")
        self.names.append(name)
        self.name_set.add(name)
        self.parents.append(parent)
        self.offsets.append(offset)
        self.channels.append(chans)
        self.open_lines.append(ln)
        return j

    def end_site(self, ln: int, toks: list[str], j: int) -> None:
        head = toks[:2]
        if head != ["End", "Site"] or not (len(toks) == 2 or toks[2:] == ["{"]):
            raise self.error(ln, f"expected 'End Site', found {_show(toks)}")
        if j in self.end_sites:
            raise self.error(ln, f"expected at most one End Site in {self.kind(j)} {self.names[j]!r}")
        self.open_brace(ln, toks[1:], "End Site")
        offset = self.parse_offset("End Site")
        cl, ctoks = self.expect_line(f"'}}' closing the End Site of line {ln}")
        if ctoks != ["}"]:
            raise self.error(cl, f"expected '}}' closing the End Site of line {ln}, found {_show(ctoks)}")
        self.end_sites[j] = np.asarray(offset, dtype=np.float64)

    def parse_offset(self, owner: str) -> list[float]:
        ln, toks = self.expect_line(f"OFFSET of {owner}")
        if toks[0] != "OFFSET":
            raise self.error(ln, f"expected OFFSET of {owner}, found {_show(toks)}")
        if len(toks) != 4:
            raise self.error(ln, f"expected 3 numbers after OFFSET, found {len(toks) - 1}")
        values = []
        for t in toks[1:]:
            try:
                v = ascii_float(t)
            except ValueError:
                raise self.error(ln, f"expected a number in OFFSET, found {t!r}") from None
            if not math.isfinite(v):
                raise self.error(ln, f"expected a finite number in OFFSET, found {t!r}")
            if abs(v) > MAX_ABS_VALUE:
                raise self.error(ln, f"expected an OFFSET value from {-MAX_ABS_VALUE:g} to {MAX_ABS_VALUE:g}, "
                                     f"found {t[:20]!r}")
            values.append(v)
        return values

    def parse_channels(self, owner: str) -> tuple[str, ...]:
        ln, toks = self.expect_line(f"CHANNELS of {owner}")
        if toks[0] != "CHANNELS":
            raise self.error(ln, f"expected CHANNELS of {owner}, found {_show(toks)}")
        if len(toks) < 2:
            raise self.error(ln, "expected a channel count after CHANNELS")
        try:
            count = ascii_int(toks[1])
        except ValueError:
            count = -1
        if count < 0 or count > 6:
            raise self.error(ln, f"expected a channel count from 0 to 6 after CHANNELS, found {toks[1]!r}")
        names = toks[2:]
        if len(names) != count:
            raise self.error(ln, f"expected {count} channel names after 'CHANNELS {count}', found {len(names)}")
        seen = set()
        for c in names:
            low = c.lower()
            if low not in _CHANNEL_INFO:
                raise self.error(ln, f"unknown channel name {c!r}: expected one of {' '.join(CHANNEL_NAMES)}")
            if low in seen:
                raise self.error(ln, f"duplicate channel name {c!r}: expected each channel at most once")
            seen.add(low)
        return tuple(names)

    def parse_frames(self) -> tuple[int, int]:
        ln, toks = self.expect_line("'Frames: <count>'")
        line = " ".join(toks)
        if not line.startswith("Frames:"):
            raise self.error(ln, f"expected 'Frames: <count>', found {_show(toks)}")
        rest = line[len("Frames:"):].split()
        try:
            if len(rest) != 1:
                raise ValueError
            n = ascii_int(rest[0])
            if n < 0:
                raise ValueError
        except ValueError:
            raise self.error(ln, f"expected a non-negative integer frame count after 'Frames:', "
                                 f"found {' '.join(rest)!r}") from None
        return n, ln

    def parse_frame_time(self) -> float:
        ln, toks = self.expect_line("'Frame Time: <seconds>'")
        line = " ".join(toks)
        if not line.startswith("Frame Time:"):
            raise self.error(ln, f"expected 'Frame Time: <seconds>', found {_show(toks)}")
        rest = line[len("Frame Time:"):].split()
        try:
            if len(rest) != 1:
                raise ValueError
            t = ascii_float(rest[0])
            if not (math.isfinite(t) and t > 0.0):
                raise ValueError
        except ValueError:
            raise self.error(ln, f"expected a positive frame time in seconds after 'Frame Time:', "
                                 f"found {' '.join(rest)[:40]!r}") from None
        if not MIN_FRAME_TIME <= t <= MAX_FRAME_TIME:
            raise self.error(ln, f"expected a frame time from {MIN_FRAME_TIME:g} to {MAX_FRAME_TIME:g} seconds "
                                 f"({1 / MAX_FRAME_TIME:g} to {1 / MIN_FRAME_TIME:g} fps) after 'Frame Time:', "
                                 f"found {rest[0][:40]!r}")
        return t

    # --- motion ------------------------------------------------------------------------
    def check_motion_size(self, n_frames: int, n_channels: int, frames_line: int) -> None:
        """The declared size and the size of the motion block, against the limits, before parsing it."""
        n_joints = len(self.names)
        if (n_frames > MAX_FRAMES or n_frames * n_channels > MAX_VALUES
                or n_frames * n_joints > MAX_JOINT_FRAMES):
            raise self.error(frames_line, f"'Frames: {n_frames}' with {n_joints} joints and {n_channels} channels "
                                          f"declares more frame lines than the reader accepts (at most "
                                          f"{MAX_FRAMES} frames, {MAX_VALUES} values and {MAX_JOINT_FRAMES} "
                                          f"frames x joints)")
        body_chars = self.n - self.pos
        room = n_frames * (n_channels * MAX_VALUE_CHARS + 2) + _BLANK_SLACK_CHARS
        if body_chars > room:
            raise self.error(frames_line, f"the motion block has {body_chars} characters, more than "
                                          f"{n_frames} frame lines of {n_channels} values can hold "
                                          f"(at most {room}: {MAX_VALUE_CHARS} per value)")
        # a frame line is at most its values' text (checked line by line on the slow path)
        self.max_line_chars = n_channels * MAX_VALUE_CHARS + 2 + 256

    def parse_motion(self, n_frames: int, n_channels: int, frames_line: int) -> np.ndarray:
        if n_channels == 0:
            item = self.next_line()
            if item is not None:
                raise self.error(item[0], "expected no frame values: the hierarchy declares 0 channels")
            return np.zeros((n_frames, 0))
        # bytes, not a StringIO (4 bytes a character); at most one row more than declared is read
        body = self.text[self.pos:].encode("utf-8")
        if n_frames > 0 and body and not body.isspace():
            try:
                with warnings.catch_warnings():
                    warnings.simplefilter("ignore")
                    motion = np.loadtxt(io.BytesIO(body), dtype=np.float64, comments=None, ndmin=2,
                                        max_rows=n_frames + 1, encoding="utf-8")
            except Exception:
                motion = None
            del body
            if (motion is not None and motion.shape == (n_frames, n_channels)
                    and (np.abs(motion) <= MAX_ABS_VALUE).all()):  # NaN fails the comparison too
                return motion
        return self.parse_motion_slowly(n_frames, n_channels, frames_line)

    def parse_motion_slowly(self, n_frames: int, n_channels: int, frames_line: int) -> np.ndarray:
        """Line by line, to find the first bad line (or, failing that, to parse the data).
        Values are kept packed (8 bytes each), never as Python lists of floats."""
        values = array.array("d")
        n_rows = 0
        while True:
            item = self.next_line()
            if item is None:
                break
            ln, toks = item
            if n_rows == n_frames:
                raise self.error(ln, f"expected end of file: 'Frames: {n_frames}' on line {frames_line} "
                                     f"declares {n_frames} frames but more frame lines follow")
            if len(toks) != n_channels:
                raise self.error(ln, f"expected {n_channels} values on frame line {n_rows + 1}, "
                                     f"found {len(toks)}")
            for k, t in enumerate(toks):
                try:
                    v = ascii_float(t)
                except ValueError:
                    raise self.error(ln, f"expected a number (value {k + 1} of frame {n_rows + 1}), "
                                         f"found {t[:20]!r}") from None
                if not math.isfinite(v):
                    raise self.error(ln, f"expected a finite number (value {k + 1} of frame "
                                         f"{n_rows + 1}), found {t[:20]!r}")
                if abs(v) > MAX_ABS_VALUE:
                    raise self.error(ln, f"expected a value from {-MAX_ABS_VALUE:g} to {MAX_ABS_VALUE:g} "
                                         f"(value {k + 1} of frame {n_rows + 1}), found {t[:20]!r}")
                values.append(v)
            n_rows += 1
        if n_rows != n_frames:
            raise self.error(frames_line, f"expected {n_frames} frame lines as declared by 'Frames: {n_frames}', "
                                          f"found {n_rows} (the file ends at line {self.lineno})")
        return np.frombuffer(values, dtype=np.float64).reshape(n_frames, n_channels).copy()


def _decode(data: bytes, path: str | None) -> str:
    nul = data.find(b"\x00")
    if nul >= 0:
        raise BVHError("binary data (NUL byte): expected a text BVH file", path, data.count(b"\n", 0, nul) + 1)
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as e:
        line = data.count(b"\n", 0, e.start) + 1
        raise BVHError(f"invalid UTF-8 (byte 0x{data[e.start]:02x}): expected a text BVH file",
                       path, line) from None
    return text


def _too_big(path: str | None, what: str) -> BVHError:
    return BVHError(f"{what} more than {MAX_TEXT_BYTES} bytes of text ({MAX_TEXT_BYTES >> 20} MiB): "
                    f"expected a smaller file (split the take)", path)


def _gunzip(f, path: str | None) -> bytes:
    """Inflate the gzip stream of the open binary file ``f``, incrementally: a stream that inflates
    past :data:`MAX_TEXT_BYTES` is abandoned there (memory and time stay bounded)."""
    start = f.tell()
    try:
        with gzip.GzipFile(fileobj=f, mode="rb") as g:
            data = g.read(MAX_TEXT_BYTES + 1)
    except (EOFError, OSError, zlib.error, ValueError) as e:
        # inflate what we can (bounded), to say on which line of the text the data stops
        f.seek(start)
        inflater = zlib.decompressobj(wbits=31)
        partial = 0
        lines = 0
        try:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                out = inflater.decompress(chunk, MAX_TEXT_BYTES - partial)
                partial += len(out)
                lines += out.count(b"\n")
                if partial >= MAX_TEXT_BYTES or inflater.unconsumed_tail:
                    break
        except zlib.error:
            pass
        line = lines + 1 if partial else None
        raise BVHError(f"corrupt or truncated gzip data ({e}): expected a complete gzip stream",
                       path, line) from None
    if len(data) > MAX_TEXT_BYTES:
        raise _too_big(path, "the gzip data inflates to")
    if data[:2] == _GZIP_MAGIC:   # said plainly, not as "binary data (NUL byte)"
        raise BVHError("a gzip file inside a gzip file: expected one level of gzip around a text BVH file", path)
    return data


def _read_bytes(f, path: str | None) -> bytes:
    """The (inflated) bytes of the open binary file ``f``, at most :data:`MAX_TEXT_BYTES`."""
    start = f.tell()
    if f.read(2) == _GZIP_MAGIC:
        f.seek(start)
        return _gunzip(f, path)
    f.seek(start)
    data = f.read(MAX_TEXT_BYTES + 1)  # not trusting the size a file reports (pipes, /dev/zero)
    if len(data) > MAX_TEXT_BYTES:
        raise _too_big(path, "the file has")
    return data


def _parse_text(text: str, path: str | None) -> Animation:
    if "\x00" in text:
        nul = text.index("\x00")
        raise BVHError("binary data (NUL byte): expected a text BVH file", path, text.count("\n", 0, nul) + 1)
    if text.startswith("\ufeff"):
        text = text[1:]
    if "\r" in text and "\n" not in text:  # classic Mac line endings
        text = text.replace("\r", "\n")
    return _Parser(text, path).parse()


def loads(text: str | bytes, path: str | os.PathLike | None = None) -> Animation:
    """Parse BVH text (``bytes`` are accepted too, gzip-compressed or not)."""
    path = None if path is None else os.fspath(path)
    if isinstance(text, (bytes, bytearray, memoryview)):
        text = _decode(_read_bytes(io.BytesIO(text), path), path)
    elif len(text) > MAX_TEXT_BYTES:
        raise _too_big(path, "the text has")
    return _parse_text(text, path)


def load(path: str | os.PathLike) -> Animation:
    """Read a ``.bvh`` file, or a gzip-compressed one (detected by its magic bytes)."""
    p = os.fspath(path)
    with open_regular(p, "BVH file") as f:   # a FIFO or a device is refused, never waited on or read forever
        if os.fstat(f.fileno()).st_size > MAX_TEXT_BYTES and f.read(2) != _GZIP_MAGIC:
            raise _too_big(p, "the file has")  # refused before reading it
        f.seek(0)
        text = _decode(_read_bytes(f, p), p)  # the bytes are freed once decoded
    return _parse_text(text, p)


# --------------------------------------------------------------------------------------
# writing
# --------------------------------------------------------------------------------------

def _fields(skel) -> tuple[list[str], np.ndarray, np.ndarray, list[tuple[str, ...]], dict, float | None]:
    if isinstance(skel, Mapping):
        get = skel.get
    else:
        def get(key, default=None):
            return getattr(skel, key, default)
    names = [str(n) for n in get("names")]
    parents = np.asarray(get("parents"), dtype=np.int64).reshape(-1)
    offsets = np.asarray(get("offsets"), dtype=np.float64).reshape(-1, 3)
    channels = [tuple(c) for c in get("channels")]
    end_sites = {int(k): np.asarray(v, dtype=np.float64).reshape(3) for k, v in (get("end_sites") or {}).items()}
    frame_time = get("frame_time")
    return names, parents, offsets, channels, end_sites, frame_time


def _depth_first_order(parents: np.ndarray) -> list[int]:
    children: list[list[int]] = [[] for _ in parents]
    roots = []
    for j, p in enumerate(parents):
        (roots if p < 0 else children[p]).append(j)
    order, stack = [], roots[::-1]
    while stack:
        j = stack.pop()
        order.append(j)
        stack.extend(children[j][::-1])
    return order


def _reordered(anim: Animation, order: list[int]) -> Animation:
    inverse = np.empty(len(order), dtype=np.int64)
    inverse[order] = np.arange(len(order))
    starts = anim._column_starts()
    cols = [c for j in order for c in range(starts[j], starts[j + 1])]
    parents = np.array([inverse[anim.parents[j]] if anim.parents[j] >= 0 else -1 for j in order], dtype=np.int64)
    return Animation(names=[anim.names[j] for j in order], parents=parents, offsets=anim.offsets[order],
                     channels=[anim.channels[j] for j in order], motion=anim.motion[:, cols],
                     frame_time=anim.frame_time,
                     end_sites={int(inverse[k]): v for k, v in anim.end_sites.items()}, path=anim.path)


def _fmt(values, precision: int) -> str:
    return " ".join(f"{float(v) + 0.0:.{precision}f}" for v in values)


def frames_field(n_frames: int) -> str:
    """The fixed-width count field of the ``Frames:`` line: ``str(n)`` padded with spaces."""
    n = int(n_frames)
    s = str(n)
    if n < 0 or len(s) > FRAMES_FIELD_WIDTH:
        raise ValueError(f"frame count {n} does not fit the {FRAMES_FIELD_WIDTH}-character Frames field")
    return s.ljust(FRAMES_FIELD_WIDTH)


def frames_field_offset(header: str) -> int:
    """Byte offset, in ``header.encode('utf-8')``, of the count field of its ``Frames:`` line."""
    idx = header.rfind("\n" + _FRAMES_PREFIX)
    if idx < 0:
        raise ValueError("no 'Frames:' line in the header")
    return len(header[:idx + 1 + len(_FRAMES_PREFIX)].encode("utf-8"))


def header_text(anim, n_frames: int | None = None, *, frame_time: float | None = None,
                precision: int = 6) -> str:
    """Everything up to and including the ``Frame Time:`` line, LF line endings.

    ``anim`` is an :class:`Animation` or any object / mapping with ``names``,
    ``parents``, ``offsets``, ``channels`` and optionally ``end_sites`` and
    ``frame_time``. ``n_frames`` defaults to ``anim.n_frames`` (0 when absent).
    The joints must be in depth-first order (as read from any BVH file), because
    the columns of the frames that follow must match the header; :func:`dumps`
    reorders an animation whose joints are not.
    The ``Frames:`` line is ``"Frames: " + frames_field(n_frames)``, see the module doc.
    """
    names, parents, offsets, channels, end_sites, ft = _fields(anim)
    if frame_time is None:
        frame_time = ft
    if frame_time is None or not (math.isfinite(float(frame_time)) and float(frame_time) > 0):
        raise ValueError(f"frame_time must be a positive number, got {frame_time!r}")
    if n_frames is None:
        n_frames = getattr(anim, "n_frames", 0) if not isinstance(anim, Mapping) else anim.get("n_frames", 0)
    J = len(names)
    if parents.shape != (J,) or offsets.shape != (J, 3) or len(channels) != J:
        raise ValueError("names, parents, offsets and channels disagree on the joint count")
    if J == 0:
        raise ValueError("a BVH file needs at least one joint")
    if any(not -1 <= p < j for j, p in enumerate(parents)) or _depth_first_order(parents) != list(range(J)):
        raise ValueError("joints are not in depth-first order (parents[j] < j and children right after "
                         "their parent's subtree); use dumps()/save(), which reorder them")
    for name in names:
        if not name.strip() or any(c in name for c in "{}\r\n") or name != name.strip():
            raise ValueError(f"joint name {name!r} cannot be written to a BVH file")
    for ch in channels:
        low = [c.lower() for c in ch]
        if any(c not in _CHANNEL_INFO for c in low) or len(set(low)) != len(low):
            raise ValueError(f"bad channel list {ch}")
    out = ["HIERARCHY"]
    depth = np.zeros(J, dtype=np.int64)
    stack: list[int] = []

    def close(k: int) -> None:
        ind = "\t" * int(depth[k])
        if k in end_sites:
            out.append(f"{ind}\tEnd Site")
            out.append(f"{ind}\t{{")
            out.append(f"{ind}\t\tOFFSET {_fmt(end_sites[k], precision)}")
            out.append(f"{ind}\t}}")
        out.append(f"{ind}}}")

    for j in range(J):
        p = int(parents[j])
        while stack and stack[-1] != p:
            close(stack.pop())
        depth[j] = 0 if p < 0 else depth[p] + 1
        ind = "\t" * int(depth[j])
        out.append(f"{ind}{'ROOT' if p < 0 else 'JOINT'} {names[j]}")
        out.append(f"{ind}{{")
        out.append(f"{ind}\tOFFSET {_fmt(offsets[j], precision)}")
        out.append(f"{ind}\tCHANNELS {len(channels[j])}" + "".join(" " + c for c in channels[j]))
        stack.append(j)
    while stack:
        close(stack.pop())
    out.append("MOTION")
    out.append(_FRAMES_PREFIX + frames_field(n_frames))
    out.append(f"Frame Time: {float(frame_time):.10g}")
    return "\n".join(out) + "\n"


def format_frames(motion_rows, precision: int = 6) -> str:
    """Frame lines for the rows of ``motion_rows`` ((F, C) or one row (C,)), each ending in LF."""
    a = np.asarray(motion_rows, dtype=np.float64)
    if a.ndim == 1:
        a = a[None]
    if a.ndim != 2:
        raise ValueError(f"motion rows must be 1-D or 2-D, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError("motion contains NaN or infinite values, which BVH cannot store")
    F, C = a.shape
    if F == 0:
        return ""
    if C == 0:
        return "\n" * F
    row = " ".join([f"%.{int(precision)}f"] * C)
    a = a + 0.0  # no '-0.000000' from negative zeros
    return "\n".join([row % tuple(r) for r in a.tolist()]) + "\n"


def dumps(anim: Animation, precision: int = 6) -> str:
    """The BVH text of ``anim`` (LF line endings, tab indentation).

    Joints are written depth-first (children in index order); an animation whose
    joints are in another order is reordered, columns included.
    """
    order = _depth_first_order(anim.parents)
    if order != list(range(anim.n_joints)):
        anim = _reordered(anim, order)
    return header_text(anim, anim.n_frames, precision=precision) + format_frames(anim.motion, precision)


def save(path: str | os.PathLike, anim: Animation, precision: int = 6) -> None:
    """Write ``anim`` to ``path`` (gzip-compressed when the name ends with ``.gz``).

    The file is written to a temporary name next to it and renamed, so a crash
    never leaves a half-written file under ``path``.
    """
    p = Path(os.fspath(path))
    data = dumps(anim, precision).encode("utf-8")
    if p.name.endswith(".gz"):
        data = gzip.compress(data, compresslevel=6, mtime=0)
    write_bytes_atomic(p, data)

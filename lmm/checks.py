"""Data checks: what in a motion capture take (or a recording) a motion matching database should not hold.

Every rule works on the global joint positions of one take at its own frame rate, in metres, vectorised
over frames, so the same code judges source takes (:func:`check_take`, :func:`check_manifest`) and
recordings of a running character (:func:`motion_report`). Analysis, not data: it judges takes with
:mod:`lmm.metrics`' rules and measures what the used ranges cover with :mod:`lmm.coverage`'s speed x turn
cells.

Kinds of finding (frames are the file's own, ``[start_frame, end_frame)`` half-open as manifest ranges):

* ``calibration_pose``: the T-pose a capture session starts (and often ends) with: both hands within
  ``TPOSE_HAND_HEIGHT_M`` of shoulder height, further apart than ``TPOSE_HAND_SPAN_M``, hips nearly still;
* ``airborne``: both toes more than ``AIRBORNE_HEIGHT_M`` above the take's ground level (a low percentile
  of its toe heights) for longer than a jump, ``AIRBORNE_MIN_S``: climbing, vaulting, standing on an obstacle;
* ``contact_sliding``: a toe at ground level moving faster than ``SLIDE_SPEED_M_S`` for ``SLIDE_MIN_S``;
* ``speed_outlier`` / ``turn_outlier``: horizontal hips speed or facing turn rate far above the rest of
  the take (``OUTLIER_FACTOR`` times its 99th percentile, and above an absolute floor);
* ``frame_rate``: a frame time that is not a common capture rate;
* ``unit_scale``: a standing height that, with the manifest's ``unit_scale``, is not a human's.
"""
from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from lmm import quat
from lmm.coverage import Heatmap, speed_turn_heatmap
from lmm.data import bvh
from lmm.data.motion_files import load_motion
from lmm.data.manifest import Manifest
from lmm.data.build import MIN_RANGE_FRAMES
from lmm.errors import InputError
from lmm.skeleton import bones_with_defaults, joint_of_role

# -- thresholds (metres, seconds) ---------------------------------------------------------------------
GROUND_PERCENTILE = 2.0          # a take's ground level: this percentile of the lower toe's height
TPOSE_HAND_HEIGHT_M = 0.25       # hands within this of shoulder height ...
TPOSE_HAND_SPAN_M = 1.2          # ... and further apart than this
TPOSE_MAX_HIPS_SPEED_M_S = 0.5   # ... while the hips hardly move
TPOSE_MIN_S = 0.3
AIRBORNE_HEIGHT_M = 0.15         # both toes this far above the ground level ...
AIRBORNE_MIN_S = 0.4             # ... for longer than a jump's flight
GROUND_CONTACT_M = 0.03          # a toe within this of the ground level is at ground level
SLIDE_SPEED_M_S = 0.5            # moving faster than this along the ground ...
SLIDE_MIN_S = 0.25               # ... for this long is sliding, not a toe-off
OUTLIER_FACTOR = 1.6             # speed/turn above this times the take's 99th percentile ...
SPEED_OUTLIER_FLOOR_M_S = 4.5    # ... and above these absolute floors
TURN_OUTLIER_FLOOR_DEG_S = 900.0
OUTLIER_MIN_S = 0.2
SMOOTH_S = 0.2                   # speeds and turn rates are averaged over this window
MERGE_GAP_S = 0.2                # runs of a finding separated by less than this are one finding
COMMON_FPS = (24.0, 25.0, 30.0, 48.0, 50.0, 60.0, 90.0, 100.0, 120.0, 200.0, 240.0, 250.0)
HUMAN_HEIGHT_M = (1.0, 2.5)      # head height range of a standing adult

RAISED_LEG_M = 0.25              # a toe this far above the ground ...
RAISED_LEG_MAX_HIPS_M_S = 1.0    # ... while the hips move slower than this (not a running stride) ...
RAISED_LEG_MIN_S = 0.15          # ... for this long is a raised leg (a gesture, a step over something)
RAISED_ARM_MIN_HIPS_M_S = 2.0    # a hand above the head while running faster than this ...
RAISED_ARM_MIN_S = 0.15          # ... for this long is a raised arm
KINDS = ("calibration_pose", "airborne", "contact_sliding", "raised_leg", "raised_arm", "speed_outlier",
         "turn_outlier", "frame_rate", "unit_scale")


class CheckError(InputError):
    """A take or manifest the checks cannot read; the message names the file."""


@dataclass
class Finding:
    file: str
    kind: str
    start_frame: int
    end_frame: int          # exclusive
    detail: str
    in_used_range: bool = False
    fps: float = 0.0        # the file's frame rate (for seconds in messages; not in the JSON)

    def to_dict(self) -> dict:
        d = asdict(self)
        del d["fps"]
        return d

    def line(self) -> str:
        where = f"frames {self.start_frame}-{self.end_frame}"
        fps = self.fps
        if fps:
            where += f" ({self.start_frame / fps:.2f}-{self.end_frame / fps:.2f} s)"
        used = " [in a used range]" if self.in_used_range else ""
        return f"{self.file}: {self.kind} {where}: {self.detail}{used}"


@dataclass
class TakeSignals:
    """Per-frame signals of one take (F frames at ``fps``) that the rules threshold."""
    fps: float
    ground_m: float
    toe_height_m: np.ndarray        # (F, 2) above the ground level
    toe_speed_m_s: np.ndarray       # (F, 2) horizontal
    hips_speed_m_s: np.ndarray      # (F,) horizontal, smoothed
    turn_rate_deg_s: np.ndarray     # (F,) facing turn rate, smoothed, absolute
    turn_signed_deg_s: np.ndarray   # (F,) facing turn rate, smoothed, + toward +x (the coverage's sign)
    tpose: np.ndarray               # (F,) bool
    head_height_m: np.ndarray       # (F,) highest joint above the lower toe
    hand_over_head_m: np.ndarray | None = None   # (F,) the higher hand above the head joint (None: no such joints)


# ---------------------------------------------------------------------------------------------------
# array helpers
# ---------------------------------------------------------------------------------------------------

def runs(mask: np.ndarray, min_len: int = 1, merge_gap: int = 0) -> list[tuple[int, int]]:
    """Half-open ``[start, stop)`` runs of True in ``mask``, gaps shorter than ``merge_gap`` closed first,
    runs shorter than ``min_len`` dropped."""
    m = np.asarray(mask, dtype=bool)
    if not m.size:
        return []
    edges = np.diff(np.concatenate([[0], m.astype(np.int8), [0]]))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    if merge_gap > 0 and starts.size > 1:
        keep = (starts[1:] - stops[:-1]) >= merge_gap
        starts = np.concatenate([starts[:1], starts[1:][keep]])
        stops = np.concatenate([stops[:-1][keep], stops[-1:]])
    long = (stops - starts) >= max(min_len, 1)
    return [(int(a), int(b)) for a, b in zip(starts[long], stops[long])]


def moving_average(x: np.ndarray, window: int) -> np.ndarray:
    """Centred moving average along axis 0 (edges repeated), ``window`` frames (made odd)."""
    x = np.asarray(x, dtype=np.float64)
    window = max(int(window) | 1, 1)
    if window == 1 or x.shape[0] < 2:
        return x.copy()
    half = window // 2
    padded = np.concatenate([np.repeat(x[:1], half, axis=0), x, np.repeat(x[-1:], half, axis=0)], axis=0)
    c = np.cumsum(padded, axis=0)
    c = np.concatenate([np.zeros_like(c[:1]), c], axis=0)
    return (c[window:] - c[:-window]) / window


def horizontal_speed(positions: np.ndarray, fps: float) -> np.ndarray:
    """(F, ...) speed in the ground plane of positions (F, ..., 3), by central differences."""
    p = np.asarray(positions, dtype=np.float64)[..., [0, 2]]
    if p.shape[0] < 2:
        return np.zeros(p.shape[:-1])
    v = np.gradient(p, axis=0) * fps
    return np.linalg.norm(v, axis=-1)


def facing_turn_rate(hips_rotations: np.ndarray, fps: float, forward_axis=(0.0, 1.0, 0.0),
                     signed: bool = False) -> np.ndarray:
    """(F,) turn rate (deg/s) of the hips' forward axis projected on the ground: absolute, or ``signed``
    (+ toward +x, as :func:`lmm.coverage.trajectory_speed_turn`)."""
    fwd = quat.mul_vec(np.asarray(hips_rotations, dtype=np.float64), np.asarray(forward_axis, dtype=np.float64))
    yaw = np.unwrap(np.arctan2(fwd[:, 0], fwd[:, 2]))
    if yaw.shape[0] < 2:
        return np.zeros(yaw.shape)
    rate = np.degrees(np.gradient(yaw) * fps)
    return rate if signed else np.abs(rate)


def source_fps(frame_time: float) -> float:
    """Frames per second of a file; "Frame Time: 0.033333" means 30 fps, not 30.0003 (as the database build)."""
    fps = 1.0 / frame_time
    return float(round(fps)) if abs(fps - round(fps)) < 0.01 else fps


# ---------------------------------------------------------------------------------------------------
# signals and rules
# ---------------------------------------------------------------------------------------------------

def take_signals(global_positions: np.ndarray, global_rotations: np.ndarray | None, names: list[str], fps: float,
                 bones: dict[str, str] | None = None, forward_axis=(0.0, 1.0, 0.0),
                 ground_m: float | None = None) -> TakeSignals:
    """Per-frame signals from global positions (F, J, 3) in metres, Y up.

    ``ground_m``: the floor height; None takes the take's own ground level (a low percentile of the
    lower toe's height), which is right for source takes; recordings stand on y = 0.
    """
    bones = bones_with_defaults(bones)   # the roles the manifest does not name: their LAFAN1 names
    g = np.asarray(global_positions, dtype=np.float64)
    F = g.shape[0]
    toes = [joint_of_role(names, bones, "left_toe"), joint_of_role(names, bones, "right_toe")]
    hips = joint_of_role(names, bones, "hips")
    if None in toes or hips is None:
        raise CheckError(f"the checks need the hips and toe joints ({bones.get('hips')}, {bones.get('left_toe')}, "
                         f"{bones.get('right_toe')})")
    toe_y = g[:, toes, 1]
    if ground_m is None:
        ground_m = float(np.percentile(toe_y.min(axis=1), GROUND_PERCENTILE)) if F else 0.0
    window = max(int(round(SMOOTH_S * fps)), 1)
    hips_speed = moving_average(horizontal_speed(g[:, hips], fps), window)
    if global_rotations is not None:
        rate = facing_turn_rate(global_rotations[:, hips], fps, forward_axis, signed=True)
        turn, turn_signed = moving_average(np.abs(rate), window), moving_average(rate, window)
    else:
        turn = turn_signed = np.zeros(F)
    hand = [joint_of_role(names, bones, r) for r in ("left_hand", "right_hand", "left_shoulder", "right_shoulder")]
    if None in hand:
        tpose = np.zeros(F, dtype=bool)
    else:
        lh, rh, ls, rs = (g[:, j] for j in hand)
        tpose = ((np.abs(lh[:, 1] - ls[:, 1]) < TPOSE_HAND_HEIGHT_M) & (np.abs(rh[:, 1] - rs[:, 1]) < TPOSE_HAND_HEIGHT_M)
                 & (np.linalg.norm(lh - rh, axis=-1) > TPOSE_HAND_SPAN_M))
    head = joint_of_role(names, bones, "head")
    over = None if None in hand[:2] or head is None else g[:, hand[:2], 1].max(axis=1) - g[:, head, 1]
    return TakeSignals(fps=float(fps), ground_m=float(ground_m), toe_height_m=toe_y - ground_m, hand_over_head_m=over,
                       toe_speed_m_s=horizontal_speed(g[:, toes], fps), hips_speed_m_s=hips_speed,
                       turn_rate_deg_s=turn, turn_signed_deg_s=turn_signed, tpose=tpose, head_height_m=g[..., 1].max(axis=1) - toe_y.min(axis=1))


def find_issues(s: TakeSignals, file: str) -> list[Finding]:
    """Every finding of the motion rules (not frame rate or units) over one take's signals."""
    fps = s.fps
    frames = lambda seconds: max(int(round(seconds * fps)), 1)  # noqa: E731
    gap = frames(MERGE_GAP_S)
    out: list[Finding] = []

    still = s.tpose & (s.hips_speed_m_s < TPOSE_MAX_HIPS_SPEED_M_S)
    for a, b in runs(still, frames(TPOSE_MIN_S), gap):
        out.append(Finding(file, "calibration_pose", a, b,
                           f"arms straight out at shoulder height, {(b - a) / fps:.2f} s (trim it)"))

    low = s.toe_height_m.min(axis=1)
    for a, b in runs(low > AIRBORNE_HEIGHT_M, frames(AIRBORNE_MIN_S), gap):
        out.append(Finding(file, "airborne", a, b,
                           f"both toes above {AIRBORNE_HEIGHT_M * 100:.0f} cm for {(b - a) / fps:.2f} s "
                           f"(up to {low[a:b].max() * 100:.0f} cm): climbing, vaulting or on an obstacle"))

    sliding = ((s.toe_height_m < GROUND_CONTACT_M) & (s.toe_speed_m_s > SLIDE_SPEED_M_S)).any(axis=1)
    for a, b in runs(sliding, frames(SLIDE_MIN_S), 0):
        out.append(Finding(file, "contact_sliding", a, b,
                           f"a toe at ground level moves faster than {SLIDE_SPEED_M_S:.1f} m/s for {(b - a) / fps:.2f} s"))

    high = s.toe_height_m.max(axis=1)
    for a, b in runs((high > RAISED_LEG_M) & (s.hips_speed_m_s < RAISED_LEG_MAX_HIPS_M_S), frames(RAISED_LEG_MIN_S), gap):
        out.append(Finding(file, "raised_leg", a, b,
                           f"a toe up to {high[a:b].max() * 100:.0f} cm above the ground while the hips move slower "
                           f"than {RAISED_LEG_MAX_HIPS_M_S:g} m/s, {(b - a) / fps:.2f} s: a gesture a stop would show"))
    if s.hand_over_head_m is not None:
        up = (s.hand_over_head_m > 0.0) & (s.hips_speed_m_s > RAISED_ARM_MIN_HIPS_M_S)
        for a, b in runs(up, frames(RAISED_ARM_MIN_S), gap):
            out.append(Finding(file, "raised_arm", a, b,
                               f"a hand above the head while running, {(b - a) / fps:.2f} s"))

    for kind, signal, floor, unit in (("speed_outlier", s.hips_speed_m_s, SPEED_OUTLIER_FLOOR_M_S, "m/s"),
                                      ("turn_outlier", s.turn_rate_deg_s, TURN_OUTLIER_FLOOR_DEG_S, "deg/s")):
        if not signal.size:
            continue
        limit = max(OUTLIER_FACTOR * float(np.percentile(signal, 99)), floor)
        for a, b in runs(signal > limit, frames(OUTLIER_MIN_S), gap):
            out.append(Finding(file, kind, a, b, f"up to {signal[a:b].max():.3g} {unit} (limit {limit:.3g} {unit})"))
    out.sort(key=lambda f: (f.start_frame, KINDS.index(f.kind)))
    return out


def file_issues(file: str, frame_time: float, head_height_m: np.ndarray, n_frames: int,
                unit_scale: float) -> list[Finding]:
    """Frame-rate and unit findings over a whole file."""
    out = []
    fps = 1.0 / frame_time if frame_time > 0 else float("nan")
    if not any(abs(fps - c) <= 0.005 * c for c in COMMON_FPS):
        out.append(Finding(file, "frame_rate", 0, n_frames,
                           f"Frame Time {frame_time:g} s is {fps:.3f} fps, not a common capture rate "
                           f"({', '.join(f'{c:g}' for c in COMMON_FPS)})"))
    if head_height_m.size:
        height = float(np.median(head_height_m))
        lo, hi = HUMAN_HEIGHT_M
        if not lo <= height <= hi:
            suggest = unit_scale * 1.7 / height if height > 0 else float("nan")
            out.append(Finding(file, "unit_scale", 0, n_frames,
                               f"standing height {height:.3g} m with unit_scale {unit_scale:g} is not a person's "
                               f"({lo:g}-{hi:g} m); unit_scale {suggest:.3g} would give 1.7 m"))
    return out


def _load_take(path: Path):
    try:
        return load_motion(path)
    except bvh.BVHError as e:
        raise CheckError(str(e)) from None
    except (OSError, EOFError) as e:
        reason = e.strerror if isinstance(e, OSError) and e.strerror else str(e) or type(e).__name__
        raise CheckError(f"{path}: cannot read: {reason}") from None


def check_take(path, file: str | None = None, unit_scale: float = 0.01, bones: dict[str, str] | None = None,
               forward_axis=(0.0, 1.0, 0.0), used_ranges=None) -> tuple[list[Finding], TakeSignals]:
    """Findings over the whole take at ``path`` (named ``file`` in them), flagged where they overlap a
    ``used_ranges`` pair ``[start, stop)``; also the take's signals (for coverage)."""
    path = Path(path)
    file = file or str(path)
    anim = _load_take(path)
    g_rot, g_pos = anim.global_transforms()
    g_pos = g_pos * unit_scale
    try:
        signals = take_signals(g_pos, g_rot, anim.names, source_fps(anim.frame_time), bones, forward_axis)
    except CheckError as e:
        raise CheckError(f"{path}: {e}") from None
    findings = file_issues(file, anim.frame_time, signals.head_height_m, anim.n_frames, unit_scale)
    findings += find_issues(signals, file)
    used = [(0, anim.n_frames)] if used_ranges is None else list(used_ranges)
    for f in findings:
        f.fps = signals.fps
        f.in_used_range = any(f.start_frame < b and a < f.end_frame for a, b in used)
    return findings, signals


# ---------------------------------------------------------------------------------------------------
# a manifest: findings and coverage
# ---------------------------------------------------------------------------------------------------

@dataclass
class SourceCoverage:
    """What a manifest's used ranges cover, in source seconds: per tag, and per speed x turn cell of
    :mod:`lmm.coverage` (hips speed and facing turn rate of the takes, smoothed over ``SMOOTH_S``)."""
    seconds_per_tag: dict[str, float]
    seconds_total: float
    speed_turn: Heatmap

    def to_dict(self) -> dict:
        return {"seconds_total": self.seconds_total, "seconds_per_tag": dict(self.seconds_per_tag),
                "speed_bins_m_s": self.speed_turn.speed_edges_m_s.tolist(),
                "turn_bins_deg_s": self.speed_turn.turn_edges_deg_s.tolist(),
                "histogram_s": self.speed_turn.seconds.round(2).tolist()}


def check_manifest(manifest: Manifest, progress=None) -> tuple[list[Finding], SourceCoverage]:
    """Findings over every take of a manifest (whole files) and the coverage of the ranges it uses.

    Seconds are source seconds before mirroring (a mirrored database holds twice as many frames)."""
    findings: list[Finding] = []
    tag_seconds: dict[str, float] = {}
    speed_turn = speed_turn_heatmap([], [], 1.0)
    total = 0.0
    for i, clip in enumerate(manifest.clips):
        name = clip.source or str(clip.file)
        anim_findings, s = check_take(clip.file, name, manifest.unit_scale, manifest.bones,
                                      manifest.hips_forward_axis, used_ranges=None)
        n = s.hips_speed_m_s.shape[0]
        ranges = clip.ranges or [(0, n)]
        for k, (a, b) in enumerate(ranges):  # the ranges build-db would refuse are errors here too
            field = f"clips[{i}].ranges[{k}]" if clip.ranges else f"clips[{i}].file"
            if b > n:
                raise CheckError(f"{manifest.path}: {field}: stop {b} is past the last frame of {name} ({n} frames)")
            if b - a < MIN_RANGE_FRAMES:
                raise CheckError(f"{manifest.path}: {field}: {b - a} frames of {name}; a range needs at least "
                                 f"{MIN_RANGE_FRAMES} frames")
        for f in anim_findings:
            f.in_used_range = any(f.start_frame < b and a < f.end_frame for a, b in ranges)
        findings += anim_findings
        for k, (a, b) in enumerate(ranges):
            range_tags = clip.tags_of(k)
            b = min(b, n)
            seconds = max(b - a, 0) / s.fps
            total += seconds
            for t in (range_tags or ("untagged",)):
                tag_seconds[t] = tag_seconds.get(t, 0.0) + seconds
            speed_turn.seconds += speed_turn_heatmap(s.hips_speed_m_s[a:b], s.turn_signed_deg_s[a:b], s.fps).seconds
        if progress:
            progress(i + 1, len(manifest.clips), Path(name).name)
    return findings, SourceCoverage(dict(sorted(tag_seconds.items())), total, speed_turn)


def format_coverage(cov: SourceCoverage) -> str:
    """The coverage summary as text: seconds per tag and the speed x turn-rate table (seconds; rows up to
    the fastest one holding motion, ``.`` for an empty cell)."""
    lines = [f"coverage: {cov.seconds_total:.1f} s of source motion in used ranges (x2 when mirrored)"]
    for tag, sec in cov.seconds_per_tag.items():
        lines.append(f"  {tag:<16} {sec:7.1f} s")
    hm = cov.speed_turn
    se, te = hm.speed_edges_m_s, hm.turn_edges_deg_s
    lines.append("seconds by root speed (m/s, rows: lower edge) x turn rate (deg/s, columns: lower edge, "
                 "+ toward +x):")
    lines.append(f"  {'':>5} " + "".join(f"{t:>6g}" for t in te[:-1]))
    filled = np.flatnonzero(hm.seconds.sum(axis=1) > 0)
    for i in range(int(filled.max()) + 1 if filled.size else 0):
        lines.append(f"  {se[i]:>5g} " + "".join(f"{v:6.1f}" if v > 0 else f"{'.':>6}" for v in hm.seconds[i]))
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------
# recordings: the same rules, judged against the floor at y = 0
# ---------------------------------------------------------------------------------------------------

def motion_report(global_positions: np.ndarray, names: list[str], fps: float, bones: dict[str, str] | None = None,
                  ground_m: float | None = 0.0) -> dict:
    """Numbers a user sees as wrong motion, over global positions (F, J, 3) in metres:

    ``airborne_fraction`` (frames with both toes more than ``AIRBORNE_HEIGHT_M`` above the floor),
    ``airborne_longest_s``, ``tpose_frames`` (hands at shoulder height and far apart) and
    ``ground_toe_fast_fraction``: the ground skating of :func:`lmm.metrics.ground_skating` (the one rule
    ``run``, ``eval`` and the source takes use: toe steps within 2 cm of the toe's own floor faster than
    30 cm/s). ``ground_m``: the floor for the airborne test (0 for recordings; None: the take's own level).
    """
    from lmm.metrics import ground_skating

    s = take_signals(global_positions, None, names, fps, bones, ground_m=ground_m)
    F = s.toe_height_m.shape[0]
    air = s.toe_height_m.min(axis=1) > AIRBORNE_HEIGHT_M
    air_runs = runs(air)
    toes = [joint_of_role(names, bones, "left_toe"), joint_of_role(names, bones, "right_toe")]
    skating = ground_skating(np.asarray(global_positions, np.float64)[:, toes], fps) if F > 1 else None
    return {
        "frames": int(F), "fps": float(fps), "seconds": F / fps if fps else 0.0,
        "airborne_fraction": float(air.mean()) if F else 0.0,
        "airborne_frames": int(air.sum()),
        "airborne_longest_s": max((b - a for a, b in air_runs), default=0) / fps,
        "airborne_max_height_m": float(s.toe_height_m.min(axis=1).max()) if F else 0.0,
        "tpose_frames": int(s.tpose.sum()),
        "ground_toe_fast_fraction": float(skating["fraction"]) if skating else float("nan"),
        "ground_steps": int(skating["ground_steps"]) if skating else 0,
        "ground_skating_steps": int(skating["skating_steps"]) if skating else 0,
    }


def recording_report(path, unit_scale: float = 0.01) -> dict:
    """:func:`motion_report` of a BVH recording (centimetres, floor at y = 0)."""
    anim = _load_take(Path(path))
    return motion_report(anim.global_positions() * unit_scale, anim.names, source_fps(anim.frame_time))

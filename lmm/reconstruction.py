"""Reconstruction benchmark: how close MM and LMM come to real motion they have not seen.

For each held-out range (``lmm/data/heldout.json``: ranges the default database does not use), the
controller input is derived from the take's root path (:mod:`lmm.input_from_motion`), MM and LMM are
driven by it from a reset, and each output is compared with the take (:mod:`lmm.compare`): DTW rotation
error and position error (root-relative and world, the take moved to start where the controllers
start), the root path error (the character's root against the take's, per tick), and the ground skating
figure of both (:func:`lmm.metrics.ground_skating`). Per-frame errors are kept for plots over time.

Two baselines beside each take say how much of the pose the controllers reproduce, both as the
root-relative position error (cm) of :func:`lmm.compare.compare_motions` (the mean distance of matching
joints, each pose in its hips' heading frame), at the take's own frames:

* **mean pose**: holding the take's own mean root-relative pose (per joint, the mean position over the
  take) for the whole take: what a controller that knew the take's average and nothing else would score;
* **nearest frame**: per frame of the take, the database frame whose root-relative pose is nearest to it
  (by that error), and its error: an oracle of pose matching alone (no trajectory, no continuity), the
  best any controller playing database poses could do pose by pose (:class:`PoseOracle`; every
  ``ORACLE_STRIDE``-th frame of the take, which the table's last line and the JSON say).
"""
from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm import quat
from lmm.errors import InputError

HELDOUT_FILE = Path(__file__).resolve().parent / "data" / "heldout.json"
SHARED_PREFIX = "shared:"


def default_shared_dir() -> Path:
    """Where the ``shared:`` takes are looked up: ``$LMM_LAFAN1_DIR``, else ``../shared/data/lafan1``
    beside the repository."""
    env = os.environ.get("LMM_LAFAN1_DIR")
    if env:
        return Path(env)
    return Path(__file__).resolve().parent.parent.parent / "shared" / "data" / "lafan1"


@dataclass
class HeldOut:
    file: Path
    name: str           # as listed
    frames: tuple[int, int]
    motion: str
    note: str = ""


def load_heldout(path=HELDOUT_FILE, shared_dir=None) -> tuple[list[HeldOut], list[str]]:
    """The held-out ranges whose files exist, and a line per listed file that does not."""
    from lmm.data.jsonio import read_json

    path = Path(path)
    doc = read_json(path)
    takes = doc.get("takes") if isinstance(doc, dict) else None
    if not isinstance(takes, list) or not takes:
        raise InputError(f"{path}: field 'takes': expected a non-empty list")
    shared = Path(shared_dir) if shared_dir else default_shared_dir()
    out, missing = [], []
    for i, t in enumerate(takes):
        try:
            name, (a, b), motion = str(t["file"]), t["frames"], str(t["motion"])
            a, b = int(a), int(b)
        except (KeyError, TypeError, ValueError):
            raise InputError(f"{path}: takes[{i}]: expected file, frames [start, stop] and motion") from None
        f = shared / name[len(SHARED_PREFIX):] if name.startswith(SHARED_PREFIX) else path.parent / name
        if not f.is_file():
            missing.append(f"{name}: not found at {f} (skipped)")
            continue
        out.append(HeldOut(f, name, (a, b), motion, str(t.get("note", ""))))
    return out, missing


def _aligned_world(positions_cm: np.ndarray, start_cm: np.ndarray, yaw0: float) -> np.ndarray:
    """World positions moved so ``start_cm`` (ground) is the origin and turned by ``-yaw0``."""
    c, s = math.cos(-yaw0), math.sin(-yaw0)
    d = positions_cm - np.array([start_cm[0], 0.0, start_cm[2]])
    out = d.copy()
    out[..., 0] = c * d[..., 0] + s * d[..., 2]
    out[..., 2] = -s * d[..., 0] + c * d[..., 2]
    return out


#: the nearest-frame oracle looks at every ORACLE_STRIDE-th frame of a take: every one, as it costs about
#: 2.3 ms a frame on the default database (57,500 frames), 6 s for the 2,700 frames of the held-out takes
ORACLE_STRIDE = 1


def mean_pose_error(local_cm: np.ndarray) -> float:
    """Root-relative error (cm) of holding the mean of ``local_cm`` (F, J, 3), the take's root-relative
    joint positions, against each of its frames: mean over frames and joints of the joint distance."""
    return float(np.linalg.norm(local_cm - local_cm.mean(axis=0), axis=2).mean())


class PoseOracle:
    """The database's root-relative poses (cm, :func:`lmm.compare.motion_from_arrays`'s ``local_cm``, as
    float32) and, per pose asked about, the frame of least root-relative error and that error (float64).
    Brute force over every frame, one coordinate of one joint at a time over all frames (contiguous rows
    that stay in cache, into preallocated buffers)."""

    CHUNK = 8192

    def __init__(self, db, hips_forward_axis):
        from lmm.compare import motion_from_arrays

        parts = []
        for a in range(0, db.n_frames, self.CHUNK):
            frames = slice(a, min(a + self.CHUNK, db.n_frames))
            g_rot, g_pos = db.global_transforms(frames)
            m = motion_from_arrays("database", list(db.names), db.rotations[frames], g_rot, g_pos * 100.0,
                                   db.fps, hips_forward_axis)
            parts.append(m.local_cm.astype(np.float32))
        self.joints = m.joints
        self.local_cm = np.concatenate(parts)        # (N, J, 3)
        self._rows = np.ascontiguousarray(self.local_cm.reshape(len(self.local_cm), -1).T)   # (J * 3, N)
        n = len(self.local_cm)
        self._sum, self._sq, self._d = np.empty(n, np.float32), np.empty(n, np.float32), np.empty(n, np.float32)

    def nearest(self, pose_cm: np.ndarray) -> tuple[int, float]:
        """(frame, error in cm) of the database pose nearest ``pose_cm`` (J, 3) by root-relative error."""
        total, sq, d = self._sum, self._sq, self._d
        total[:] = 0.0
        q = np.asarray(pose_cm, np.float32).ravel()
        for j in range(0, len(q), 3):
            np.subtract(self._rows[j], q[j], out=sq)
            np.multiply(sq, sq, out=sq)
            for k in (j + 1, j + 2):
                np.subtract(self._rows[k], q[k], out=d)
                np.multiply(d, d, out=d)
                np.add(sq, d, out=sq)
            np.sqrt(sq, out=sq)
            np.add(total, sq, out=total)
        best = int(np.argmin(total))
        return best, float(np.linalg.norm(self.local_cm[best].astype(np.float64) - pose_cm, axis=1).mean())


def baselines(reference, oracle: PoseOracle | None, stride: int = ORACLE_STRIDE) -> dict:
    """The two baselines of a take's :class:`lmm.compare.Motion` (see the module doc)."""
    out = {"mean_pose_root_relative_cm": mean_pose_error(reference.local_cm)}
    if oracle is not None:
        if oracle.joints != reference.joints:
            raise InputError(f"{reference.name}: its joints differ from the database's; no nearest-frame oracle")
        ticks = np.arange(0, len(reference.local_cm), stride)
        found = [oracle.nearest(reference.local_cm[i]) for i in ticks]
        errors = np.array([e for _, e in found])
        out.update({"nearest_frame_root_relative_cm": float(errors.mean()), "nearest_frame_stride": int(stride),
                    "nearest_frame_ticks": ticks.tolist(), "nearest_frames": [f for f, _ in found],
                    "per_tick_nearest_frame_cm": errors.tolist()})
    return out


def run_take(take: HeldOut, db, features, manifest, controllers: dict, tuning=None, dt: float = 1.0 / 60.0,
             oracle: PoseOracle | None = None) -> dict:
    """One held-out range through every controller (reset first). Returns the per-take result, with the
    baselines (the nearest-frame one when an ``oracle`` is given)."""
    from lmm.compare import compare_motions, motion_from_arrays
    from lmm.data import bvh
    from lmm.input_from_motion import derive_input, take_root_path
    from lmm.metrics import ground_skating
    from lmm.runner import step_controllers

    anim = bvh.load(take.file)
    root = take_root_path(anim, manifest, take.name, take.frames)
    derived = derive_input(root, tuning, dt)
    a, b = take.frames
    g_rot, g_pos = anim.global_transforms()
    cm = manifest.unit_scale * 100.0
    world = _aligned_world(g_pos[a:b] * cm, root.positions[0] * 100.0, float(root.yaw[0]))
    # the take's rotations turned with it (only the hips' facing changes; the pose terms ignore facing)
    turn = quat.from_axis_angle(np.array([0.0, 1.0, 0.0]), np.array(-float(root.yaw[0])))
    rot = quat.mul(np.broadcast_to(turn, g_rot[a:b].shape), g_rot[a:b])
    reference = motion_from_arrays(take.name, list(anim.names), anim.local_rotations()[a:b], rot, world,
                                   1.0 / anim.frame_time, manifest.hips_forward_axis)
    toe_names = [manifest.bones["left_toe"], manifest.bones["right_toe"]]
    take_toes = g_pos[a:b][:, [anim.names.index(n) for n in toe_names]] * manifest.unit_scale
    result = {"take": take.name, "frames": [a, b], "motion": take.motion, "seconds": (b - a) * anim.frame_time,
              "input_path_error": derived.path_error(),
              "source_ground_skating": ground_skating(take_toes, 1.0 / anim.frame_time)["fraction"],
              "baselines": baselines(reference, oracle), "controllers": {}}
    for c in controllers.values():
        c.reset()
    n = len(derived.inputs)
    names = list(db.names)
    toes = [names.index(t) for t in toe_names]
    collected = {k: {"local": np.zeros((n, len(names), 4)), "rot": np.zeros((n, len(names), 4)),
                     "pos": np.zeros((n, len(names), 3))} for k in controllers}
    for i, inp in enumerate(derived.inputs):
        poses, _, _ = step_controllers(controllers, inp, dt)
        for k, pose in poses.items():
            collected[k]["local"][i] = pose.local_rotations
            collected[k]["rot"][i] = pose.global_rotations
            collected[k]["pos"][i] = pose.global_positions
    for k, arrays in collected.items():
        out = motion_from_arrays(k, names, arrays["local"], arrays["rot"], arrays["pos"] * 100.0, 1.0 / dt,
                                 manifest.hips_forward_axis)
        cmp = compare_motions(reference, out)
        root_err = np.linalg.norm((arrays["pos"][:, 0] - derived.reference_positions)[:, [0, 2]], axis=1)
        result["controllers"][k] = {
            "rotation_error_rad": cmp["rotation_error_rad"],
            "position_error_cm": cmp["position_error_cm"],
            "root_path_error_cm": float(root_err.mean() * 100.0),
            "ground_skating": ground_skating(arrays["pos"][:, toes], 1.0 / dt)["fraction"],
            "per_frame_rotation_error_rad": cmp["per_frame"]["rotation_error_rad"],
            "per_frame_root_relative_cm": cmp["per_frame"]["root_relative_cm"],
        }
    result["compare_fps"] = float(min(1.0 / anim.frame_time, 1.0 / dt))
    return result


#: the baselines' figures (cm) that summaries average and tables show, in this order
BASELINES = ("mean_pose_root_relative_cm", "nearest_frame_root_relative_cm")


def _baseline_cells(b: dict) -> str:
    return " / ".join(f"{b[k]:.1f}" if k in b else "-" for k in BASELINES)


def summarize(results: list[dict], controller_names) -> dict:
    """Means per motion type and overall (each take weighted by its seconds)."""
    groups: dict[str, list[dict]] = {}
    for r in results:
        groups.setdefault(r["motion"], []).append(r)
    groups["all"] = list(results)
    out = {}
    for g, rs in groups.items():
        w = np.array([r["seconds"] for r in rs])
        row = {"takes": len(rs), "seconds": float(w.sum())}
        for k in controller_names:
            pick = lambda f: float(np.average([f(r["controllers"][k]) for r in rs], weights=w))  # noqa: E731
            row[k] = {"rotation_error_rad": pick(lambda c: c["rotation_error_rad"]),
                      "root_relative_cm": pick(lambda c: c["position_error_cm"]["root_relative"]),
                      "world_cm": pick(lambda c: c["position_error_cm"]["world"]),
                      "root_path_error_cm": pick(lambda c: c["root_path_error_cm"]),
                      "ground_skating": pick(lambda c: c["ground_skating"])}
        row["source_ground_skating"] = float(np.average([r["source_ground_skating"] for r in rs], weights=w))
        row["baselines"] = {k: float(np.average([r["baselines"][k] for r in rs], weights=w))
                            for k in BASELINES if all(k in r["baselines"] for r in rs)}
        out[g] = row
    return out


def format_table(results: list[dict], summary: dict, controller_names) -> str:
    """Per take and per motion type: rotation (rad), root-relative / world position (cm), root path (cm)
    and ground skating, one column group per controller; the baselines' root-relative errors beside."""
    cols = " | ".join(f"{k.upper()} rot rad, pos cm (rel/world), root cm, skate" for k in controller_names)
    lines = [f"| take | motion | s | input path cm | {cols} | rel cm: mean pose / nearest frame | source skate |",
             "|---|---|---|---|" + "---|" * len(controller_names) + "---|---|"]

    def cells(c):
        return (f"{c['rotation_error_rad']:.3f}, {c['position_error_cm']['root_relative']:.1f} / "
                f"{c['position_error_cm']['world']:.0f}, {c['root_path_error_cm']:.1f}, {c['ground_skating']:.3f}")
    for r in results:
        a, b = r["frames"]
        name = r["take"].split("/")[-1].replace(".bvh.gz", "").replace(".bvh", "")
        lines.append(f"| {name} [{a}:{b}] | {r['motion']} | {r['seconds']:.1f} | "
                     f"{r['input_path_error']['position_mean_m'] * 100:.1f} | "
                     + " | ".join(cells(r["controllers"][k]) for k in controller_names)
                     + f" | {_baseline_cells(r['baselines'])} | {r['source_ground_skating']:.3f} |")
    for g, row in summary.items():
        lines.append(f"| **{g}** ({row['takes']} takes) | | {row['seconds']:.1f} | | " + " | ".join(
            f"{row[k]['rotation_error_rad']:.3f}, {row[k]['root_relative_cm']:.1f} / {row[k]['world_cm']:.0f}, "
            f"{row[k]['root_path_error_cm']:.1f}, {row[k]['ground_skating']:.3f}" for k in controller_names)
            + f" | {_baseline_cells(row['baselines'])} | {row['source_ground_skating']:.3f} |")
    strides = {r["baselines"].get("nearest_frame_stride") for r in results} - {None}
    if strides:
        every = "every frame" if strides == {1} else f"every {'/'.join(map(str, sorted(strides)))}th frame"
        lines.append(f"Baselines: the take's mean pose held; the database's nearest pose ({every} of each take).")
    return "\n".join(lines)


def to_json(results, summary) -> str:
    return json.dumps({"takes": results, "summary": summary}, indent=1)

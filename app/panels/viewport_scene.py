"""What the 3D view draws of a character, as viewer renderables: skeleton and ghost, and its markers
(trajectories, features, contacts, trails), worked out without GL (:func:`character_parts`) and batched
with the others' (:mod:`.viewport_markers`)."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lmm import quat

from .common import darker, lighter
from .viewport_markers import Markers


def feature_markers(features, normalized, root_pos, root_rot, bone_positions: dict) -> dict:
    """World-space markers of a normalised feature vector, by channel kind.

    Returns ``{"points": (N,3), "arrows": (origins (M,3), vectors (M,3)), "traj": (T,3),
    "traj_dirs": (T,3)}``: bone positions as points, bone velocities as arrows starting at the
    bone (``bone_positions[channel.bone]`` when known, else at the feature's own position) scaled to
    0.1 s of motion, and trajectory points/directions on the ground.
    """
    raw = features.denormalize(np.asarray(normalized, np.float32)).astype(np.float64)
    rot_t = quat.to_matrix(np.asarray(root_rot, np.float64)).T     # row vectors: v @ R^T == R v
    root = np.asarray(root_pos, np.float64)
    points, origins, vectors, traj, dirs = [], [], [], [], []
    positions_by_bone = {}
    for ch, s in zip(features.layout, features.slices):
        if ch.kind == "bone_position":
            p = root + raw[s] @ rot_t
            points.append(p)
            positions_by_bone[ch.bone] = p
    for ch, s in zip(features.layout, features.slices):
        v = raw[s]
        if ch.kind == "bone_velocity":
            start = bone_positions.get(ch.bone, positions_by_bone.get(ch.bone))
            if start is not None:
                origins.append(start)
                vectors.append((v @ rot_t) * 0.1)
        elif ch.kind.startswith("trajectory"):
            xz = v.reshape(-1, 2)
            ground = np.zeros((len(xz), 3))
            ground[:, 0], ground[:, 2] = xz[:, 0], xz[:, 1]
            if ch.kind == "trajectory_position":
                traj.append(root + ground @ rot_t)
            else:
                dirs.append(ground @ rot_t)
    z3 = np.zeros((0, 3))
    return {"points": np.array(points) if points else z3,
            "arrows": (np.array(origins) if origins else z3, np.array(vectors) if vectors else z3),
            "traj": np.concatenate(traj) if traj else z3, "traj_dirs": np.concatenate(dirs) if dirs else z3}


class CharacterDrawing:
    """A character's skeleton and ghost; its markers go into the shared :class:`MarkerBatch`."""

    def __init__(self, viewer, ctx, parents, color, names=None, style: str = "capsules", shadow: bool = True,
                 body_radii=None):
        self.color = color
        # joint names hide the unnamed simulation bone, body radii size the body parts (see viewer.Skeleton)
        self.skeleton = viewer.Skeleton(ctx, parents, color=color, names=names, style=style, shadow=shadow,
                                        body_radii=body_radii, joint_radius=0.028, bone_radius=0.02)
        self.ghost = viewer.Skeleton(ctx, parents, color=lighter(color, 0.55), alpha=0.32, names=names,
                                     body_radii=body_radii, style=style, shadow=shadow, thickness=0.9,
                                     joint_radius=0.024, bone_radius=0.017)
        self.traj_color = lighter(color, 0.35)
        self.trail_color = darker(color, 0.3)

    def all(self):
        return [self.skeleton, self.ghost]

    def set_style(self, style: str, shadow: bool) -> None:
        for s in self.all():
            s.style = style
            s.shadow = shadow

    def hide(self) -> None:
        self.skeleton.visible = False
        self.ghost.visible = False


SIM_COLOR = (0.95, 0.88, 0.3)
MATCHED_COLOR = (0.9, 0.9, 0.92)
FEATURE_COLOR = (0.85, 0.4, 0.95)
CONTACT_COLOR = (0.3, 0.95, 0.4)
LOCKED_COLOR = (0.2, 0.9, 0.95)
LEGEND = (("simulation object", SIM_COLOR), ("desired trajectory", (0.85, 0.85, 0.85)),
          ("matched frame's trajectory", MATCHED_COLOR), ("foot contact", CONTACT_COLOR),
          ("locked", LOCKED_COLOR), ("pose features", FEATURE_COLOR), ("ghost = matched pose", (0.75, 0.75, 0.8)))


class FeaturePlan:
    """Where :func:`feature_markers`' channels lie in a feature vector, as index arrays, so a frame's
    markers are a few gathers and matrix products (the same numbers, in one call per kind)."""

    def __init__(self, features, db):
        def dims(kind, width):
            idx = [np.arange(s.start, s.stop).reshape(-1, width) for ch, s in zip(features.layout, features.slices)
                   if ch.kind == kind]
            return np.concatenate(idx) if idx else np.zeros((0, width), np.intp)

        bones = dict(_feature_bones(features, db))
        position_bones = [ch.bone for ch in features.layout if ch.kind == "bone_position"]
        self.positions = dims("bone_position", 3)
        self.velocities, self.velocity_starts = [], []
        # a velocity arrow starts at the bone's joint in the pose (index < J), else at its position feature
        n_joints = len(db.parents)
        for ch, s in zip(features.layout, features.slices):
            if ch.kind != "bone_velocity":
                continue
            if ch.bone in bones:
                start = bones[ch.bone]
            elif ch.bone in position_bones:
                start = n_joints + len(position_bones) - 1 - position_bones[::-1].index(ch.bone)
            else:
                continue
            self.velocities.append(np.arange(s.start, s.stop))
            self.velocity_starts.append(start)
        self.velocities = np.array(self.velocities, np.intp).reshape(-1, 3)
        self.velocity_starts = np.array(self.velocity_starts, np.intp)
        self.trajectory = dims("trajectory_position", 2)
        self.directions = dims("trajectory_direction", 2)
        self.features, self.db = features, db


_PLANS: dict = {}


def _plan(features, db) -> FeaturePlan:
    hit = _PLANS.get((id(features), id(db)))
    if hit is None or hit.features is not features or hit.db is not db:
        if len(_PLANS) > 16:
            _PLANS.clear()
        hit = _PLANS[(id(features), id(db))] = FeaturePlan(features, db)
    return hit


def _on_ground(xz, rot_t, origin=None):
    """Ground points (x, z) of the root's frame in the world (``origin`` None: directions)."""
    ground = np.zeros((len(xz), 3))
    ground[:, 0], ground[:, 2] = xz[:, 0], xz[:, 1]
    out = ground @ rot_t
    return out if origin is None else origin + out


@dataclass(frozen=True)
class CharacterParts:
    """What the 3D view draws of a character at a tick, worked out without GL (:func:`character_parts`):
    its skeleton's and ghost's poses (the ghost None when hidden) and its markers."""
    skeleton: object          # viewer SkeletonPose
    ghost: object | None
    markers: Markers


def apply_character(d: CharacterDrawing, parts: CharacterParts) -> None:
    """Hand a character's worked-out skeleton and ghost to its renderables (the GL thread's share; its
    markers go into the batch with the other characters')."""
    d.skeleton.visible = True
    d.skeleton.update(parts.skeleton)
    d.ghost.visible = parts.ghost is not None
    if parts.ghost is not None:
        d.ghost.update(parts.ghost)


def character_parts(d: CharacterDrawing, snap, off, show: dict, features, db, trail) -> CharacterParts:
    """A character's skeleton and ghost poses and markers at a snapshot (``show``: toggle -> on;
    ``trail``: its recent root positions, or None): numpy only, no GL and no change to ``d``, so the
    studio's tick worker can work it out for the next frame while the GUI draws."""
    b = Markers()
    pose = snap.pose
    g = np.asarray(pose.global_positions, np.float64)
    skeleton = d.skeleton.prepare(g + off)
    ghost = d.ghost.prepare(np.asarray(snap.matched_pose_positions, np.float64) + off) if show["ghost"] else None
    # simulation object and its predicted trajectory
    if show["trajectory"]:
        lift = off + _LIFT
        sim = np.asarray(snap.simulation_position, np.float64) + lift
        traj = np.asarray(snap.trajectory_positions, np.float64) + lift
        # the trajectory's rotations and the simulation bone's in one conversion: their +Z axes
        rots = np.concatenate([np.asarray(snap.trajectory_rotations, np.float64).reshape(-1, 4),
                               np.asarray(snap.simulation_rotation, np.float64).reshape(1, 4)])
        axes = _z_axes(rots)
        b.add_polyline(np.concatenate([sim[None], traj]), d.traj_color)
        b.add_spheres(traj, 0.045, d.traj_color)
        b.add_arrows(traj, axes[:-1] * 0.35, d.traj_color)
        b.add_spheres(sim, 0.06, SIM_COLOR)
        b.add_arrows(np.array([sim, sim]), np.array([axes[-1] * 0.5, np.asarray(snap.desired_velocity) * 0.25]),
                     SIM_COLOR)
    matched, current = show["matched"] and features is not None, show["features"] and features is not None
    if matched or current:
        plan = _plan(features, db)
        root = g[0]
        rot_t = _rotation_t(pose.global_rotations[0])  # v @ R^T == R v
        # both vectors denormalised in one call: element by element the same arithmetic, half the
        # numpy calls
        wanted = ([snap.matched_features] if matched else []) + ([snap.current_features] if current else [])
        raws = features.denormalize(np.asarray(wanted, np.float32)).astype(np.float64)
        # where the matched frame's own future goes (its features, placed at the character)
        if matched:
            raw = raws[0]
            up = off + _MATCHED_LIFT
            n = min(len(plan.trajectory), len(plan.directions))
            traj = _on_ground(raw[plan.trajectory], rot_t, root)
            b.add_spheres(traj + up, 0.028, MATCHED_COLOR)
            b.add_arrows(traj[:n] + up, _on_ground(raw[plan.directions[:n]], rot_t) * 0.28, MATCHED_COLOR)
        # the pose features of the playing frame: foot positions and foot/hip velocities
        if current:
            raw = raws[-1]
            points = root + raw[plan.positions] @ rot_t
            b.add_spheres(points + off, 0.035, FEATURE_COLOR)
            if len(plan.velocity_starts):
                starts = np.concatenate([g, points])[plan.velocity_starts]
                b.add_arrows(starts + off, (raw[plan.velocities] @ rot_t) * 0.1, FEATURE_COLOR)
    if show["contacts"]:
        contacts, locked = snap.foot_contacts, snap.foot_locked
        if contacts[0] or contacts[1]:
            toes = g[_toe_bones(db)]
            for i in range(2):
                if contacts[i]:
                    b.add_spheres(toes[i] + off, 0.05, LOCKED_COLOR if locked[i] else CONTACT_COLOR)
    if trail is not None:
        if trail.ndim == 2:
            trail = trail[np.isfinite(trail).all(axis=1)]
            if len(trail) >= 2:
                b.add_polyline(trail[::3] + (off + _TRAIL_LIFT), d.trail_color)
    return CharacterParts(skeleton, ghost, b)


def _z_axes(q: np.ndarray) -> np.ndarray:
    """(N, 3) +Z axes of (N, 4) quaternions: ``quat.to_matrix(q)[:, :, 2]``, the same arithmetic without
    the other six entries."""
    w, x, y, z = q.T
    return np.stack([2 * (x * z + w * y), 2 * (y * z - w * x), 1 - 2 * (x * x + y * y)], axis=-1)


def _rotation_t(q) -> np.ndarray:
    """``quat.to_matrix(q).T`` of one quaternion (w, x, y, z), in Python floats: the same arithmetic
    (IEEE doubles either way), without numpy's per-call cost on nine single numbers."""
    w, x, y, z = (float(v) for v in q)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    return np.array([[1 - 2 * (yy + zz), 2 * (xy + wz), 2 * (xz - wy)],
                     [2 * (xy - wz), 1 - 2 * (xx + zz), 2 * (yz + wx)],
                     [2 * (xz + wy), 2 * (yz - wx), 1 - 2 * (xx + yy)]])


_LIFT = np.array([0.0, 0.02, 0.0])
_MATCHED_LIFT = np.array([0.0, 0.035, 0.0])
_TRAIL_LIFT = np.array([0.0, 0.01, 0.0])
_BONES: dict = {}


def _feature_bones(features, db) -> list:
    """``[(bone name, joint index)]`` of the feature channels' bones that ``db`` has (cached)."""
    key = ("features", id(features), id(db))
    hit = _BONES.get(key)
    if hit is None or hit[0] is not features or hit[1] is not db:
        pairs = []
        for ch in features.layout:
            if ch.bone:
                try:
                    pairs.append((ch.bone, db.bone(ch.bone)))
                except KeyError:
                    pass
        if len(_BONES) > 64:
            _BONES.clear()
        hit = _BONES[key] = (features, db, pairs)
    return hit[2]


def _toe_bones(db) -> list:
    """Joint indices of the left and right toes (cached; KeyError when ``db`` has none)."""
    key = ("toes", id(db))
    hit = _BONES.get(key)
    if hit is None or hit[1] is not db:
        hit = _BONES[key] = (None, db, [db.bone("left_toe"), db.bone("right_toe")])
    return hit[2]


SIDE_OFFSET_M = 1.6         # side by side: each character this far to the right of the one before
TRAIL_SECONDS = 4.0


class Characters:
    """Every running controller's character in the 3D view, side by side (each :data:`SIDE_OFFSET_M` to
    the right of the one before) or overlaid."""

    def __init__(self, engine):
        self.engine = engine                # app.panels.base.EngineFacts: db, dt, features_of
        self.drawings: dict[str, CharacterDrawing] = {}
        self.side_by_side = True

    def add(self, viewer, gl, scene, name: str, color, body_style: dict) -> None:
        d = CharacterDrawing(viewer, gl, self.engine.db.parents, color, **body_style)
        self.drawings[name] = d
        scene.add(*d.all())

    def offset_of(self, name: str) -> np.ndarray:
        names = list(self.drawings)
        if not self.side_by_side or len(names) < 2:
            return np.zeros(3)
        i = names.index(name) if name in names else 0
        return np.array([SIDE_OFFSET_M * i, 0.0, 0.0])

    def parts(self, name: str, snap, view, show: dict) -> CharacterParts:
        """:func:`character_parts` of a character at the view's tick, with its trail when shown."""
        trail = None
        if show["trail"]:
            n = int(TRAIL_SECONDS / self.engine.dt)
            trail = view.history.window(name, "root_position", view.tick_number, n)
        return character_parts(self.drawings[name], snap, self.offset_of(name), show, self.engine.features_of(name),
                               self.engine.db, trail)

    def label_anchor(self, name: str, snap) -> np.ndarray:
        """Where a character's name label hangs: above its highest joint."""
        g = np.asarray(snap.pose.global_positions, np.float64)
        return g[g[:, 1].argmax()] + self.offset_of(name) + [0, 0.25, 0]

    def update(self, view, show: dict, prepared: dict | None, drawn: dict, roots: list) -> list:
        """Place every character at the view's tick (``prepared``: parts worked out on the tick worker, by
        name); their roots go into ``drawn`` and ``roots``. Returns their markers, or None when every
        shown character's were prepared (the prepared join of them all is then used)."""
        tick = view.tick
        all_prepared = True
        markers = []
        for name, d in self.drawings.items():
            snap = tick.snapshots.get(name) if tick is not None else None
            if snap is None:
                d.hide()
                continue
            off = self.offset_of(name)
            parts = prepared.get(name) if prepared is not None else None
            all_prepared = all_prepared and parts is not None
            parts = parts or self.parts(name, snap, view, show)
            apply_character(d, parts)
            markers.append(parts.markers)
            roots.append(np.asarray(snap.pose.global_positions[0], np.float64) + off)
            drawn["roots"][name] = [float(x) for x in snap.pose.global_positions[0]]
            drawn["offsets"][name] = [float(x) for x in off]
        return None if all_prepared else markers

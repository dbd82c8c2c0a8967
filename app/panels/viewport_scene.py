"""What the 3D view draws of a character, as viewer renderables: skeleton and ghost, and every marker
(trajectories, features, contacts, trails) batched into one sphere, one arrow and one line renderable."""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from lmm import quat

from .common import darker, lighter


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


class Markers:
    """Spheres, arrows and polylines gathered as arrays with (count, size, colour) runs: what
    :class:`MarkerBatch` draws; a character's own markers can be gathered apart (on the tick worker,
    see :func:`character_parts`) and added to the batch in one call."""

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        # each add keeps its points and one (count, size, colour) run; flush repeats the runs
        self._centers, self._sphere_runs = [], []
        self._origins, self._vectors, self._arrow_runs = [], [], []
        self._segments, self._segment_runs = [], []

    def add_spheres(self, centers, radius: float, color) -> None:
        c = np.asarray(centers, np.float64).reshape(-1, 3)
        if len(c):
            self._centers.append(c)
            self._sphere_runs.append((len(c), radius, tuple(color[:3])))

    def add_arrows(self, origins, vectors, color) -> None:
        o = np.asarray(origins, np.float64).reshape(-1, 3)
        v = np.asarray(vectors, np.float64).reshape(-1, 3)
        n = min(len(o), len(v))
        if n:
            self._origins.append(o[:n])
            self._vectors.append(v[:n])
            self._arrow_runs.append((n, 0.0, tuple(color[:3])))

    def add_polyline(self, points, color) -> None:
        p = np.asarray(points, np.float64).reshape(-1, 3)
        if len(p) >= 2:
            seg = np.empty((2 * (len(p) - 1), 3))
            seg[0::2] = p[:-1]
            seg[1::2] = p[1:]
            self._segments.append(seg)
            self._segment_runs.append((len(seg), 0.0, tuple(color[:3])))

    def compacted(self) -> "Markers":
        """The same markers with each kind's arrays joined into one (``flush`` then copies nothing)."""
        out = Markers()
        for name in ("_centers", "_origins", "_vectors", "_segments"):
            arrays = getattr(self, name)
            setattr(out, name, [np.concatenate(arrays)] if len(arrays) > 1 else list(arrays))
        out._sphere_runs, out._arrow_runs = list(self._sphere_runs), list(self._arrow_runs)
        out._segment_runs = list(self._segment_runs)
        return out

    def extend(self, other: "Markers") -> None:
        """Add every marker of ``other`` (after this one's)."""
        self._centers += other._centers
        self._sphere_runs += other._sphere_runs
        self._origins += other._origins
        self._vectors += other._vectors
        self._arrow_runs += other._arrow_runs
        self._segments += other._segments
        self._segment_runs += other._segment_runs


def _joined(arrays: list) -> np.ndarray:
    return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)


class MarkerBatch(Markers):
    """Every marker of every character, gathered per frame and drawn with one sphere, one arrow and
    one line renderable (few draw calls matter on software GL, where each costs about a millisecond)."""

    def __init__(self, viewer, ctx):
        self.spheres = viewer.Spheres(ctx, radius=0.04)
        self.arrows = viewer.Arrows(ctx, shaft_radius=0.011, head_radius=0.032, head_length=0.07)
        self.lines = viewer.Lines(ctx, width_px=2.5)
        self._expanded: dict = {}
        super().__init__()

    def renderables(self):
        return [self.lines, self.spheres, self.arrows]

    def clear(self) -> None:
        super().clear()
        self._arrow_geometry = None

    def prepare_arrows(self, markers: Markers) -> Markers:
        """``markers`` compacted, with its arrows' geometry worked out for this batch's arrows (see
        ``Arrows.prepare``): safe on another thread; ``extend`` by it, and ``flush`` uses that geometry
        when no other arrow was added."""
        out = markers.compacted()
        if out._origins:
            out.arrow_geometry = (out._origins[0], self.arrows.prepare(out._origins[0], out._vectors[0]))
        return out

    def extend(self, other: Markers) -> None:
        had = bool(self._origins)
        super().extend(other)
        if other._origins:
            self._arrow_geometry = None if had else getattr(other, "arrow_geometry", None)

    def _repeat(self, runs):
        """(per-item sizes (N,), per-item colours (N, 3)) of a list of (count, size, colour) runs; the
        runs are the same from frame to frame, so their expansions are kept (never written to)."""
        key = tuple(runs)
        hit = self._expanded.get(key)
        if hit is None:
            counts = [r[0] for r in runs]
            hit = (np.repeat(np.array([r[1] for r in runs], np.float64), counts),
                   np.repeat(np.array([r[2] for r in runs], np.float64), counts, axis=0))
            # read-only: the renderables then know the same array means the same values and keep
            # the columns they wrote from it
            for a in hit:
                a.flags.writeable = False
            if len(self._expanded) > 64:
                self._expanded.clear()
            self._expanded[key] = hit
        return hit

    def flush(self) -> None:
        z3 = np.zeros((0, 3))
        if self._centers:
            radii, colors = self._repeat(self._sphere_runs)
            self.spheres.update(_joined(self._centers), radii, colors)
        else:
            self.spheres.update(z3)
        if self._origins:
            geometry = self._arrow_geometry
            if geometry is not None and (len(self._origins) != 1 or geometry[0] is not self._origins[0]):
                geometry = None     # arrows were added after the prepared ones
            self.arrows.update(_joined(self._origins), _joined(self._vectors), self._repeat(self._arrow_runs)[1],
                               prepared=None if geometry is None else geometry[1])
        else:
            self.arrows.update(z3, z3)
        if self._segments:
            self.lines.update(_joined(self._segments), mode="segments", colors=self._repeat(self._segment_runs)[1])
        else:
            self.lines.update(z3, mode="segments")


class CharacterDrawing:
    """A character's skeleton and ghost; its markers go into the shared :class:`MarkerBatch`."""

    def __init__(self, viewer, ctx, parents, color, names=None, style: str = "capsules", shadow: bool = True):
        self.color = color
        # joint names size the body parts and hide the unnamed simulation bone (see viewer.Skeleton)
        self.skeleton = viewer.Skeleton(ctx, parents, color=color, names=names, style=style, shadow=shadow,
                                        joint_radius=0.028, bone_radius=0.02)
        self.ghost = viewer.Skeleton(ctx, parents, color=lighter(color, 0.55), alpha=0.32, names=names,
                                     style=style, shadow=shadow, thickness=0.9,
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


PREVIEW_SPACING_M = 1.3     # preview ghosts stand this far apart, to the inspected character's side
PREVIEW_LIFT = np.array([0.0, 0.025, 0.0])


def preview_placement(anchor_pos, anchor_rot, slot: int) -> tuple[np.ndarray, np.ndarray]:
    """Where preview ghost ``slot`` stands: (origin (3,), rotation matrix (3, 3)) in the world.

    The ghost faces the way the anchor (the inspected character's simulation bone) faces and stands
    ``PREVIEW_SPACING_M * (slot + 1)`` to the anchor's left along world -X (the side-by-side view puts
    the second character to the right), so every ghost follows the character of the displayed tick."""
    origin = np.asarray(anchor_pos, np.float64) * np.array([1.0, 0.0, 1.0])
    origin = origin + np.array([-PREVIEW_SPACING_M * (slot + 1), 0.0, 0.0])
    return origin, quat.to_matrix(np.asarray(anchor_rot, np.float64))


def place(points, origin, rotation) -> np.ndarray:
    """Points of a ghost's own frame (root at the origin facing +Z) in the world."""
    p = np.asarray(points, np.float64).reshape(-1, 3)
    return p @ np.asarray(rotation).T + origin


class PreviewDrawings:
    """The preview ghosts the panels ask for (``Actions.set_preview``): one skeleton per shown pose
    (made when a pose with another skeleton arrives), their trajectories and points in the shared
    :class:`MarkerBatch`."""

    def __init__(self, viewer, ctx, scene):
        self.viewer, self.ctx, self.scene = viewer, ctx, scene
        self.skeletons: list = []          # viewer.Skeleton per slot
        self._parents: list = []           # parents each slot's skeleton was made for

    def _skeleton(self, slot: int, pose, style: str, shadow: bool):
        parents = np.asarray(pose.parents, np.int64)
        while len(self.skeletons) <= slot:
            self.skeletons.append(None)
            self._parents.append(None)
        if self.skeletons[slot] is None or not np.array_equal(self._parents[slot], parents):
            if self.skeletons[slot] is not None:
                self.scene.remove(self.skeletons[slot])
                self.skeletons[slot].release()
            sk = self.viewer.Skeleton(self.ctx, parents, color=pose.color, alpha=0.6,
                                      names=list(pose.names) if pose.names is not None else None, style=style,
                                      shadow=shadow, joint_radius=0.024, bone_radius=0.017)
            self.scene.add(sk)
            self.skeletons[slot], self._parents[slot] = sk, parents
        sk = self.skeletons[slot]
        sk.color = pose.color
        sk.style, sk.shadow = style, shadow
        return sk

    def update(self, poses, batch: MarkerBatch, anchor_pos, anchor_rot, style: str, shadow: bool) -> list[dict]:
        """Draw ``poses`` (a list of :class:`app.panels.base.PreviewPose`) beside the anchor; returns what
        was drawn per slot (label, world root position and head position) for labels and tests."""
        drawn = []
        for slot, pose in enumerate(poses):
            origin, rot = preview_placement(anchor_pos, anchor_rot, slot)
            sk = self._skeleton(slot, pose, style, shadow)
            world = place(pose.positions, origin, rot)
            sk.visible = True
            sk.update(world)
            traj_color = lighter(pose.color, 0.3)
            if pose.trajectory is not None and len(pose.trajectory):
                traj = place(pose.trajectory, origin, rot) + PREVIEW_LIFT
                batch.add_polyline(np.vstack([origin[None] + PREVIEW_LIFT, traj]), traj_color)
                batch.add_spheres(traj, 0.035, traj_color)
                if pose.directions is not None and len(pose.directions) == len(traj):
                    batch.add_arrows(traj, place(pose.directions, np.zeros(3), rot) * 0.3, traj_color)
            if pose.points is not None and len(pose.points):
                batch.add_spheres(place(pose.points, origin, rot), 0.03, FEATURE_COLOR)
            head = world[int(np.argmax(world[:, 1]))]
            drawn.append({"label": pose.label, "root": [float(x) for x in world[0]],
                          "origin": [float(x) for x in origin], "head": [float(x) for x in head]})
        for sk in self.skeletons[len(poses):]:
            if sk is not None:
                sk.visible = False
        return drawn

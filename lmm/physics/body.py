"""A MuJoCo body for any BVH skeleton, and the map from a pose to its ``qpos``.

:func:`build_body` turns a skeleton (names, parents, offsets in metres) into an MJCF model (text) and a
compiled ``mujoco.MjModel`` wrapped in a :class:`Body`:

* **World.** Y is up as in our data (gravity ``0 -9.81 0``); the floor is the plane ``y = 0``.
* **Bodies.** One MuJoCo body per skeleton joint of the hips' subtree (a database's ground-projected
  "simulation" bone above the hips is left out); the hips carry a free joint, every other joint a ball
  joint with a loose cone limit (:data:`JOINT_LIMIT_DEG`). Body frames are the skeleton's joint frames, so
  a ball joint's quaternion is the joint's local rotation and the rest pose is ``qpos0``.
* **Geometry.** A capsule along each bone (joint to child) whose radius depends on the segment
  (:data:`SEGMENT_RADIUS_M`, scaled by the body's height); a sphere on a leaf joint (head, hands); a box
  under each foot (ankle to toe joint) and under each toe, lying flat on the floor in a standing pose.
  Body geoms collide with the floor only, not with each other.
* **Masses.** The total mass (default 70 kg) split by segment fractions of body mass (Winter,
  *Biomechanics and Motor Control of Human Movement*, table 4.1: :data:`SEGMENT_MASS_FRACTIONS`), each
  segment's mass spread over its geoms by volume; MuJoCo derives the inertia from the geoms.
* **Segments.** From the key joints (:data:`lmm.skeleton.KEY_ROLES`: the skeleton's roles, found by name
  when no bones table names them):
  the two joints above a foot are thigh and shank, the two above a hand upper arm and forearm, the joints
  between the arms' branch and the head (and the head's subtree) the head and neck, a foot with its
  subtree the foot, a hand with its subtree the hand; everything else (pelvis, spine, clavicles) the trunk.
* **Feet.** The sole's direction and the ankle's height come from a standing pose when ``stance`` (the
  global positions and rotations of some frames of a motion of this skeleton) is given: the frames where
  each foot is lowest. The ankle height is kept within half and twice the anthropometric one (0.039 of
  the body height, Drillis and Contini), so a file floating or sunk as a whole still gets feet of a
  human size. Without ``stance`` the rest pose's down direction and the anthropometric height are used.

Bad skeletons raise :class:`BodyError` (one line): key joints not found by name, a zero-length limb
bone, a foot with no toe or end site to size its sole.

Everything but :func:`build_body`'s compile step is numpy; ``mujoco`` is imported lazily
(:func:`lmm.physics.require_mujoco`).
"""
from __future__ import annotations

from dataclasses import dataclass, field
from xml.sax.saxutils import quoteattr

import numpy as np

from lmm import quat
from lmm.errors import InputError
from lmm.physics import require_mujoco
from lmm.skeleton import (KEY_ROLES, SIDES, Skeleton, SkeletonMatchError, ancestors, children, find_toe,
                          guess_unit_scale, leg_length, subtree)

GRAVITY_M_S2 = 9.81
DEFAULT_TOTAL_MASS_KG = 70.0
JOINT_LIMIT_DEG = 150.0          # the cone a ball joint may swing in: loose, mocap poses stay inside it
MIN_BONE_M = 1e-3                # shorter bones get no capsule; a limb bone this short is an error
ANKLE_HEIGHT_FRACTION = 0.039    # ankle joint height / body height (Drillis and Contini 1966)
HIP_TO_ANKLE_FRACTION = 0.491    # (hip joint height - ankle height) / body height, same source
REFERENCE_HEIGHT_M = 1.75        # the body the radii below are given for
FLOOR_FRICTION = 1.0

# fractions of total body mass (Winter, table 4.1); limb segments are per side; they sum to 1
SEGMENT_MASS_FRACTIONS = {
    "head": 0.081, "trunk": 0.497,
    "upper_arm": 0.028, "forearm": 0.016, "hand": 0.006,
    "thigh": 0.100, "shank": 0.0465, "foot": 0.0145,
}
# capsule / sphere radius of each segment for a 1.75 m body
SEGMENT_RADIUS_M = {
    "head": 0.095, "neck": 0.05, "trunk": 0.085,
    "upper_arm": 0.045, "forearm": 0.037, "hand": 0.04,
    "thigh": 0.07, "shank": 0.05, "foot": 0.03,
}
FOOT_HALF_WIDTH_M = 0.045        # half the width of a sole box for a 1.75 m body
HEEL_FRACTION = 0.35             # heel behind the ankle, as a fraction of the ankle-to-toe-joint length
TOE_FRACTION = 0.35              # toe box length, same fraction


class BodyError(InputError):
    """A skeleton a body cannot be built for; ``str(e)`` names the skeleton (path) and the joint."""


@dataclass(eq=False)
class Body:
    """A MuJoCo body of a skeleton. Arrays indexed by skeleton joint hold -1 for joints left out.

    ``qpos`` layout: the hips' free joint first (position xyz, quaternion wxyz: 7 values; 6 dofs: linear
    velocity in the world frame, angular velocity in the hips' frame), then one ball joint per other joint
    (quaternion wxyz: 4 values; 3 dofs, angular velocity in the joint's frame), in skeleton order.
    """

    model: object                    # mujoco.MjModel
    xml: str                         # the MJCF it was compiled from
    names: list[str]                 # the skeleton's joint names
    parents: np.ndarray              # (J,) the skeleton's parents
    offsets_m: np.ndarray            # (J, 3) the skeleton's offsets in metres
    joints: np.ndarray               # (B,) the skeleton joints that have a body, hips first
    root: int                        # the skeleton joint with the free joint (the hips)
    key_joints: dict[str, int]       # hips, head, left_hand, ... (skeleton joint indices)
    body_id: np.ndarray              # (J,) MuJoCo body id of each skeleton joint
    qpos_adr: np.ndarray             # (J,) first qpos of each joint (root: 7 values, others: 4)
    dof_adr: np.ndarray              # (J,) first dof of each joint (root: 6, others: 3)
    segment: list[str]               # (J,) segment name of each joint ("" when left out)
    segment_mass_kg: dict[str, float]
    total_mass: float                # kg
    height_m: float                  # the body height the anthropometric sizes come from
    foot_joints: dict[str, tuple[int, ...]]   # side -> (foot, toe) skeleton joints (toe when present)
    foot_geoms: dict[str, list[int]]          # side -> MuJoCo geom ids of the sole boxes
    floor_geom: int                           # MuJoCo geom id of the floor plane
    sole_joint: np.ndarray           # (P,) skeleton joint each sole point rides on
    sole_local: np.ndarray           # (P, 3) the sole points (bottom corners of the boxes) in that joint's frame
    sole_side: np.ndarray            # (P,) 0 left foot, 1 right foot
    extras: dict = field(default_factory=dict)

    @property
    def nq(self) -> int:
        return int(self.model.nq)

    @property
    def nv(self) -> int:
        return int(self.model.nv)

    @property
    def weight_n(self) -> float:
        """Body weight in newtons (the unit of residual forces)."""
        return self.total_mass * GRAVITY_M_S2

    def qpos_from_pose(self, global_pos, global_rot) -> np.ndarray:
        """``qpos`` of a pose given as global joint positions ``(..., J, 3)`` (metres, Y up) and global
        rotations ``(..., J, 4)`` (wxyz) of the skeleton; leading dimensions (frames) are kept.

        Only the hips' position is read from ``global_pos``: the other joints sit at the skeleton's offsets.
        Consecutive frames (axis 0 of a 3-D input) get quaternions in one hemisphere.
        """
        pos = np.asarray(global_pos, dtype=np.float64)
        rot = quat.normalize(np.asarray(global_rot, dtype=np.float64))
        J = len(self.names)
        if pos.shape[-2:] != (J, 3) or rot.shape[-2:] != (J, 4):
            raise ValueError(f"pose shapes {pos.shape} and {rot.shape}: expected (..., {J}, 3) and (..., {J}, 4)")
        lead = rot.shape[:-2]
        qpos = np.empty(lead + (self.nq,))
        r = self.root
        qpos[..., 0:3] = pos[..., r, :]
        qpos[..., 3:7] = rot[..., r, :]
        others = self.joints[1:]
        local = quat.inv_mul(rot[..., self.parents[others], :], rot[..., others, :])
        for k, j in enumerate(others):
            a = self.qpos_adr[j]
            qpos[..., a:a + 4] = local[..., k, :]
        if len(lead) == 1 and lead[0] > 1:
            adr = [3] + [int(self.qpos_adr[j]) for j in others]
            quats = quat.unroll(np.stack([qpos[:, a:a + 4] for a in adr], axis=1), axis=0)
            for k, a in enumerate(adr):
                qpos[:, a:a + 4] = quats[:, k]
        return qpos

    def sole_points(self, global_pos, global_rot) -> np.ndarray:
        """World positions ``(..., P, 3)`` of the sole points (box bottom corners) in a pose."""
        pos = np.asarray(global_pos, dtype=np.float64)[..., self.sole_joint, :]
        rot = np.asarray(global_rot, dtype=np.float64)[..., self.sole_joint, :]
        return pos + quat.mul_vec(rot, self.sole_local)


# ---------------------------------------------------------------------------------------------------
# the skeleton's segments
# ---------------------------------------------------------------------------------------------------

def skeleton_segments(names, parents, key: dict[str, int], path="") -> tuple[list[str], list[str]]:
    """(segment, side) of every joint (see the module doc); joints outside the hips' subtree get ""."""
    J = len(names)
    hips = key["hips"]
    inside = set(subtree(parents, hips))
    segment = ["trunk" if j in inside else "" for j in range(J)]
    side = ["" for _ in range(J)]
    for k in ("head", "left_hand", "right_hand", "left_foot", "right_foot"):
        if key[k] not in inside:
            raise BodyError(f"{path}: the {k.replace('_', ' ')} ({names[key[k]]}) is not below the hips "
                            f"({names[hips]}): cannot build a body with the hips as root")
    head_chain = ancestors(parents, key["head"])
    for s in SIDES:
        foot, hand = key[f"{s}_foot"], key[f"{s}_hand"]
        leg = ancestors(parents, foot)
        leg = leg[:leg.index(hips)]                          # shank joint, thigh joint, (hip joints)
        arm_all = ancestors(parents, hand)
        arm = [a for a in arm_all if a not in head_chain]   # below the branch point
        for seg, chain in (("shank", leg[:1]), ("thigh", leg[1:2]), ("forearm", arm[:1]), ("upper_arm", arm[1:2])):
            for j in chain:
                segment[j], side[j] = seg, s
        for j in subtree(parents, foot):
            segment[j], side[j] = "foot", s
        for j in subtree(parents, hand):
            segment[j], side[j] = "hand", s
    # neck: the joints between the arms' branch point and the head
    arm_chain = set(ancestors(parents, key["left_hand"])) | set(ancestors(parents, key["right_hand"]))
    for j in head_chain:
        if j in arm_chain or j == hips:
            break
        segment[j] = "neck"
    for j in subtree(parents, key["head"]):
        segment[j] = "head"
    return segment, side


# ---------------------------------------------------------------------------------------------------
# geometry
# ---------------------------------------------------------------------------------------------------

@dataclass
class _Geom:
    joint: int
    kind: str                      # capsule, sphere, box
    segment: str                   # mass group ("thigh", "head", "trunk", "neck", ...)
    side: str
    fromto: np.ndarray | None = None
    pos: np.ndarray | None = None
    size: np.ndarray | None = None
    xaxis: np.ndarray | None = None
    yaxis: np.ndarray | None = None
    foot: str = ""                 # side when a sole box
    mass: float = 0.0

    def volume(self) -> float:
        if self.kind == "capsule":
            r = self.size[0]
            length = float(np.linalg.norm(self.fromto[3:] - self.fromto[:3]))
            return np.pi * r * r * length + 4.0 / 3.0 * np.pi * r ** 3
        if self.kind == "sphere":
            return 4.0 / 3.0 * np.pi * self.size[0] ** 3
        return 8.0 * float(np.prod(self.size))


def _unit(v):
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-12 else None


def _flat_frames(stance, foot, toe) -> np.ndarray:
    """Frames of ``stance`` where a foot stands flat: the fifth of the frames where the ankle and the toe
    (when present) move least, among those where the ankle is no higher than its median."""
    pos = stance[0]
    if len(pos) < 3:
        return np.arange(len(pos))
    tracked = [foot] if toe is None else [foot, toe]
    step = np.linalg.norm(np.gradient(pos[:, tracked], axis=0), axis=-1).sum(axis=1)
    low = pos[:, foot, 1] <= np.median(pos[:, foot, 1])
    cut = np.percentile(step[low], 20)
    return np.flatnonzero(low & (step <= cut))


def _stance_down_height(stance, j, frames) -> tuple[np.ndarray, float] | None:
    """Down direction in joint ``j``'s frame and its height (m), over ``frames`` of ``stance``."""
    if stance is None or len(frames) == 0:
        return None
    pos, rot = stance
    down = _unit(quat.inv_mul_vec(rot[frames, j], np.array([0.0, -1.0, 0.0])).mean(axis=0))
    return (down, float(np.median(pos[frames, j, 1]))) if down is not None else None


def _sole_boxes(names, parents, offsets, end_sites, foot, toe, scale, ankle_h0, stance, path, side):
    """The sole box of a foot (ankle to toe joint, or to the end site) and of its toe, in their frames."""
    forward_vec = offsets[toe] if toe is not None else end_sites.get(foot)
    if forward_vec is None or np.linalg.norm(forward_vec) < MIN_BONE_M:
        raise BodyError(f"{path}: the {side} foot ({names[foot]}) has no toe joint or end site to size its sole")
    frames = _flat_frames(stance, foot, toe) if stance is not None else None
    measured = _stance_down_height(stance, foot, frames)
    if measured is None:
        down, height = np.array([0.0, -1.0, 0.0]), ankle_h0
    else:
        down, height = measured
    clamped = float(np.clip(height, 0.5 * ankle_h0, 2.0 * ankle_h0))
    shift = height - clamped                      # how far the stance floats (+) or sinks (-) as a whole
    f = _unit(forward_vec - np.dot(forward_vec, down) * down)
    if f is None:
        raise BodyError(f"{path}: the {side} foot ({names[foot]}) points straight down in its standing pose")
    length = float(np.dot(forward_vec, f))
    heel = HEEL_FRACTION * length
    toe_len = TOE_FRACTION * length
    half_w = FOOT_HALF_WIDTH_M * scale
    half_h = 0.25 * clamped
    s = np.cross(down, f)
    tip = length if toe is not None else length + toe_len
    boxes = [_Geom(foot, "box", "foot", side, pos=f * (tip - heel) / 2 + down * (clamped - half_h),
                   size=np.array([(tip + heel) / 2, half_w, half_h]), xaxis=f, yaxis=s, foot=side)]
    if toe is not None:
        measured_t = _stance_down_height(stance, toe, frames)
        toe_depth = float(np.dot(offsets[toe], down))        # how far below the ankle the toe joint sits
        if measured_t is None:
            down_t, height_t = down, clamped - toe_depth
        else:
            down_t, height_t = measured_t[0], measured_t[1] - shift
        height_t = max(height_t, 0.005)
        ft = _unit(offsets[toe] - np.dot(offsets[toe], down_t) * down_t)
        ft = f if ft is None else ft
        half_ht = 0.01 * scale
        boxes.append(_Geom(toe, "box", "foot", side, pos=ft * toe_len / 2 + down_t * (height_t - half_ht),
                           size=np.array([toe_len / 2, half_w, half_ht]), xaxis=ft, yaxis=np.cross(down_t, ft),
                           foot=side))
    return boxes


def _box_bottom_corners(g: _Geom) -> np.ndarray:
    down = np.cross(g.xaxis, g.yaxis)            # box z = x cross y = -down x f x ... see below
    # x = f, y = down x f  ->  z = f x (down x f) = down (f unit, perpendicular to down)
    c = g.pos + down * g.size[2]
    return np.array([c + sx * g.size[0] * g.xaxis + sy * g.size[1] * g.yaxis
                     for sx in (-1, 1) for sy in (-1, 1)])


def build_body(skeleton: Skeleton, total_mass: float = DEFAULT_TOTAL_MASS_KG, *, stance=None,
               end_sites_m=None, joint_limit_deg: float = JOINT_LIMIT_DEG, path: str = "") -> Body:
    """A :class:`Body` for a :class:`lmm.skeleton.Skeleton` (its offsets taken in metres through its
    ``unit_scale``; its key joints :data:`lmm.skeleton.KEY_ROLES` from its roles). ``stance``: optional
    ``(global_pos (F, J, 3) m, global_rot (F, J, 4))`` of a motion of this skeleton, to lay the soles flat
    (see the module doc). ``end_sites_m``: optional ``{joint: offset}`` (m), sizing a foot without a toe
    joint. ``path`` names the skeleton in errors. Raises :class:`BodyError` (one line) for a skeleton it
    cannot build, and :class:`lmm.physics.PhysicsUnavailable` when mujoco is not installed."""
    names, parents, offsets = skeleton.names, skeleton.parents, skeleton.offsets_m
    J = len(names)
    if not (np.isfinite(total_mass) and total_mass > 0):
        raise BodyError(f"{path}: total mass {total_mass} kg: expected a positive number")
    end_sites = {int(k): np.asarray(v, dtype=np.float64).reshape(3) for k, v in (end_sites_m or {}).items()}
    if stance is not None:
        stance = (np.asarray(stance[0], dtype=np.float64).reshape(-1, J, 3),
                  quat.normalize(np.asarray(stance[1], dtype=np.float64).reshape(-1, J, 4)))
    try:
        key = skeleton.require(KEY_ROLES, path)
    except SkeletonMatchError as e:
        raise BodyError(str(e)) from None
    segment, side = skeleton_segments(names, parents, key, path)
    hips = key["hips"]
    joints = np.array(subtree(parents, hips), dtype=np.int64)

    # limb bones must have a length: a capsule from each limb joint to the next joint of its chain
    for j in joints:
        if segment[j] in ("thigh", "shank", "upper_arm", "forearm"):
            nxt = [k for k in children(parents, j) if segment[k] != "" and
                   any(key[f"{side[j]}_{e}"] in subtree(parents, k) for e in ("foot", "hand"))]
            for k in nxt:
                if np.linalg.norm(offsets[k]) < MIN_BONE_M:
                    raise BodyError(f"{path}: the bone {names[j]} -> {names[k]} has zero length "
                                    f"({1000 * np.linalg.norm(offsets[k]):.2g} mm): cannot size the "
                                    f"{side[j]} {segment[j].replace('_', ' ')}")
    # hip-to-ankle length: thigh bone (the shank joint's offset) + shank bone (the foot's offset), mean of sides
    leg_len = leg_length(parents, offsets, key)
    if leg_len < 10 * MIN_BONE_M:
        raise BodyError(f"{path}: the legs ({names[key['left_foot']]}, {names[key['right_foot']]}) have no length")
    height = leg_len / HIP_TO_ANKLE_FRACTION
    scale = height / REFERENCE_HEIGHT_M
    ankle_h0 = ANKLE_HEIGHT_FRACTION * height

    geoms: list[_Geom] = []
    feet: dict[str, tuple[int, ...]] = {}
    for s in SIDES:
        foot = key[f"{s}_foot"]
        toe = find_toe(names, parents, foot)
        feet[s] = (foot,) if toe is None else (foot, toe)
        geoms += _sole_boxes(names, parents, offsets, end_sites, foot, toe, scale, ankle_h0, stance, path, s)
    boxed = {g.joint for g in geoms}
    for j in joints:
        seg = segment[j]
        radius = SEGMENT_RADIUS_M[seg] * scale
        if seg == "foot":
            if j not in boxed:       # joints below the toe: a small sphere for the mass
                geoms.append(_Geom(j, "sphere", seg, side[j], pos=np.zeros(3), size=np.array([0.5 * radius])))
            continue
        made = False
        for k in children(parents, j):
            length = float(np.linalg.norm(offsets[k]))
            if length < MIN_BONE_M:
                continue
            # a neck bone's capsule is the neck's; the head's sphere sits on the head joint
            geoms.append(_Geom(j, "capsule", seg, side[j], fromto=np.r_[np.zeros(3), offsets[k]],
                               size=np.array([radius])))
            made = True
        if not made:
            tip = end_sites.get(j)
            direction = _unit(tip) if tip is not None else None
            if direction is None:
                direction = _unit(offsets[j]) if j != hips else None
            centre = np.zeros(3) if direction is None else direction * (0.8 * radius)
            geoms.append(_Geom(j, "sphere", seg, side[j], pos=centre, size=np.array([radius])))

    # masses: segment fractions (per side for limbs), spread by volume; the neck is part of the head
    group_fraction = {}
    for g in geoms:
        seg = "head" if g.segment == "neck" else g.segment
        group_fraction[(seg, g.side)] = SEGMENT_MASS_FRACTIONS[seg]
    total_fraction = sum(group_fraction.values())
    group_volume: dict[tuple[str, str], float] = {}
    for g in geoms:
        k = ("head" if g.segment == "neck" else g.segment, g.side)
        group_volume[k] = group_volume.get(k, 0.0) + g.volume()
    segment_mass: dict[str, float] = {}
    for g in geoms:
        k = ("head" if g.segment == "neck" else g.segment, g.side)
        g.mass = total_mass * group_fraction[k] / total_fraction * g.volume() / group_volume[k]
        label = f"{k[1]}_{k[0]}" if k[1] else k[0]
        segment_mass[label] = segment_mass.get(label, 0.0) + g.mass

    xml, geom_names = _mjcf(names, parents, offsets, joints, hips, geoms, joint_limit_deg)
    mujoco = require_mujoco("building a physics body")
    try:
        model = mujoco.MjModel.from_xml_string(xml)
    except ValueError as e:       # a generated model MuJoCo refuses is a bug, but say which skeleton
        raise BodyError(f"{path}: MuJoCo refused the body built for this skeleton: {str(e).splitlines()[0]}") from None

    body_id = np.full(J, -1, dtype=np.int64)
    qpos_adr = np.full(J, -1, dtype=np.int64)
    dof_adr = np.full(J, -1, dtype=np.int64)
    for j in joints:
        b = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, _body_name(names, j))
        body_id[j] = b
        jid = model.body_jntadr[b]
        qpos_adr[j] = model.jnt_qposadr[jid]
        dof_adr[j] = model.jnt_dofadr[jid]
    foot_geoms = {s: [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, n)
                      for g, n in zip(geoms, geom_names) if g.foot == s] for s in SIDES}
    sole_joint, sole_local, sole_side = [], [], []
    for g in geoms:
        if g.foot:
            corners = _box_bottom_corners(g)
            sole_joint += [g.joint] * len(corners)
            sole_local.append(corners)
            sole_side += [SIDES.index(g.foot)] * len(corners)
    return Body(model=model, xml=xml, names=names, parents=parents, offsets_m=offsets, joints=joints, root=hips,
                key_joints=key, body_id=body_id, qpos_adr=qpos_adr, dof_adr=dof_adr,
                segment=[f"{side[j]}_{segment[j]}" if side[j] else segment[j] for j in range(J)],
                segment_mass_kg=segment_mass, total_mass=float(total_mass), height_m=float(height),
                foot_joints=feet, foot_geoms=foot_geoms,
                floor_geom=mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, "floor"),
                sole_joint=np.asarray(sole_joint, dtype=np.int64), sole_local=np.concatenate(sole_local),
                sole_side=np.asarray(sole_side, dtype=np.int64))


# ---------------------------------------------------------------------------------------------------
# MJCF text
# ---------------------------------------------------------------------------------------------------

def _body_name(names, j) -> str:
    return f"j{j}_{names[j]}"


def _v(a) -> str:
    return " ".join(f"{float(x):.6g}" for x in np.asarray(a).reshape(-1))


def _mjcf(names, parents, offsets, joints, hips, geoms, joint_limit_deg) -> tuple[str, list[str]]:
    """The MJCF text of the body, and the name given to each geom (in ``geoms`` order)."""
    by_joint: dict[int, list[int]] = {}
    for i, g in enumerate(geoms):
        by_joint.setdefault(g.joint, []).append(i)
    geom_names = [f"g{i}_{g.segment}{'_' + g.side if g.side else ''}" for i, g in enumerate(geoms)]
    lines = [
        '<mujoco model="lmm-body">',
        '  <compiler angle="degree" autolimits="true"/>',
        f'  <option timestep="0.002" gravity="0 {-GRAVITY_M_S2:g} 0" integrator="implicitfast"/>',
        '  <default>',
        '    <joint armature="0.01"/>',
        # body geoms collide with the floor only: contype 2 / conaffinity 1 never matches itself
        f'    <geom contype="2" conaffinity="1" condim="3" friction="{FLOOR_FRICTION:g} 0.005 0.0001"/>',
        '  </default>',
        '  <worldbody>',
        '    <light pos="0 4 2" dir="0 -1 -0.5"/>',
        # the plane's normal is its z axis: turned -90 degrees about x it points up (+Y)
        '    <geom name="floor" type="plane" size="0 0 1" quat="0.707107 -0.707107 0 0" contype="1" conaffinity="2"/>',
    ]
    inside = set(int(j) for j in joints)

    def emit(j, depth):
        pad = "  " * depth
        pos = np.zeros(3) if j == hips else offsets[j]
        lines.append(f'{pad}<body name={quoteattr(_body_name(names, j))} pos="{_v(pos)}">')
        if j == hips:
            lines.append(f'{pad}  <freejoint name="root"/>')
        else:
            lines.append(f'{pad}  <joint name={quoteattr(_body_name(names, j))} type="ball" range="0 {joint_limit_deg:g}"/>')
        for i in by_joint.get(j, []):
            g = geoms[i]
            attrs = f'name="{geom_names[i]}" type="{g.kind}" mass="{g.mass:.9g}"'
            if g.kind == "capsule":
                attrs += f' fromto="{_v(g.fromto)}" size="{_v(g.size)}"'
            elif g.kind == "sphere":
                attrs += f' pos="{_v(g.pos)}" size="{_v(g.size)}"'
            else:
                attrs += f' pos="{_v(g.pos)}" size="{_v(g.size)}" xyaxes="{_v(g.xaxis)} {_v(g.yaxis)}"'
            lines.append(f"{pad}  <geom {attrs}/>")
        for k in children(parents, j):
            if k in inside:
                emit(k, depth + 1)
        lines.append(f"{pad}</body>")

    emit(hips, 2)
    lines += ['  </worldbody>', '</mujoco>', '']
    return "\n".join(lines), geom_names


# ---------------------------------------------------------------------------------------------------
# bodies of the things we hold: a BVH animation, a motion database
# ---------------------------------------------------------------------------------------------------

def body_for_animation(anim, unit_scale: float | None = None, total_mass: float = DEFAULT_TOTAL_MASS_KG):
    """``(body, global_pos_m, global_rot, unit_scale)`` of a :class:`lmm.data.bvh.Animation`: its soles laid
    from its own standing frames; ``unit_scale`` (metres per file unit) guessed when None."""
    path = anim.path or "<animation>"
    if unit_scale is None:
        unit_scale = guess_unit_scale(anim.names, anim.parents, anim.offsets)
        if unit_scale is None:
            raise BodyError(f"{path}: the legs have no length: cannot guess the file's unit")
    rot, pos = anim.global_transforms()
    pos = pos * unit_scale
    skeleton = Skeleton.by_synonyms(anim.names, anim.parents, anim.offsets, unit_scale)
    body = build_body(skeleton, total_mass, stance=(pos, rot),
                      end_sites_m={k: v * unit_scale for k, v in anim.end_sites.items()}, path=path)
    return body, pos, rot, float(unit_scale)


def body_for_database(db, total_mass: float = DEFAULT_TOTAL_MASS_KG, stance_frames: int = 4000) -> Body:
    """The body of a :class:`lmm.data.database.Database`'s skeleton (metres; its simulation bone left out;
    its roles from the database's ``bone_roles``, the others by name), soles laid from up to
    ``stance_frames`` of its frames spread over the database."""
    frames = np.unique(np.linspace(0, db.n_frames - 1, min(stance_frames, db.n_frames)).astype(np.int64))
    rot, pos = db.global_transforms(frames)
    skeleton = Skeleton.from_bones(db.names, db.parents, db.positions[0], db.bone_roles)
    return build_body(skeleton, total_mass, stance=(pos, rot), path=f"database {db.name}")

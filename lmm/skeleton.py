"""The skeleton: joint names, parents, rest offsets, the file's unit, and the joints' roles.

A **role** says what a joint is (``hips``, ``spine``, ``left_foot``, ``left_toe``, ``left_hand``, ``head``...).
Roles are resolved once, here, and read by index everywhere else:

* from a **bones table** (role -> joint name): a manifest's ``bones`` or a database's ``bone_roles``, over the
  LAFAN1 names of :data:`DEFAULT_BONES` for the roles it does not name;
* for any other file, from **name synonyms** (:data:`ROLE_SYNONYMS`: ``LeftHand``, ``mixamorig:LeftHand``,
  ``l_wrist`` are all the left hand).

The tree helpers (:func:`children`, :func:`ancestors`, :func:`subtree`, :func:`chain`) are free functions over a
parents array (parents before children, -1 for a root) so the per-tick code can call them without a
:class:`Skeleton`; the class binds them to one skeleton. :func:`guess_unit_scale` is the one guess of a file's
unit, :func:`body_radii` the one table of body-part thickness by joint name (the viewer draws it as capsules).

This module sits at the bottom of the engine: numpy and :mod:`lmm.errors` only.
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from lmm.errors import InputError

#: role -> the joint's name in LAFAN1: the manifest's default ``bones`` and the data checks' fallbacks
DEFAULT_BONES = {
    "hips": "Hips", "spine": "Spine2", "left_foot": "LeftFoot", "right_foot": "RightFoot",
    "left_toe": "LeftToe", "right_toe": "RightToe",
    "left_hand": "LeftHand", "right_hand": "RightHand", "left_shoulder": "LeftArm", "right_shoulder": "RightArm",
    "head": "Head",
}
#: the roles a manifest must name (the database build reads them)
# The database's first joint: the root's projection on the ground that the controllers move (Holden et al.'s
# "simulation bone"); files written by this program and others' root-motion skeletons name it so.
SIMULATION_BONE = "Simulation"
SIMULATION_BONE_NAMES = ("Simulation", "simulation", "Root", "root")

MANIFEST_ROLES = ("hips", "spine", "left_foot", "right_foot", "left_toe", "right_toe")
#: the six joints any human skeleton is matched by (motion search's windows, the physics body)
KEY_ROLES = ("hips", "head", "left_hand", "right_hand", "left_foot", "right_foot")
SIDES = ("left", "right")

#: role -> accepted normalized names (lower case, letters and digits only, a namespace like "mixamorig:" dropped)
ROLE_SYNONYMS = {
    "hips": ("hips", "hip", "pelvis", "root", "bip01pelvis"),
    "head": ("head", "bip01head"),
    "left_hand": ("lefthand", "lhand", "handl", "leftwrist", "lwrist", "wristl", "bip01lhand"),
    "right_hand": ("righthand", "rhand", "handr", "rightwrist", "rwrist", "wristr", "bip01rhand"),
    "left_foot": ("leftfoot", "lfoot", "footl", "leftankle", "lankle", "anklel", "bip01lfoot"),
    "right_foot": ("rightfoot", "rfoot", "footr", "rightankle", "rankle", "ankler", "bip01rfoot"),
}

UNIT_SCALES = (1.0, 0.1, 0.0254, 0.01, 0.001)   # metres per file unit: m, dm, inch, cm, mm
HUMAN_LEG_M = 0.86                                # hip-to-ankle length of a 1.75 m body
HUMAN_HEIGHT_M = 1.75                             # the rest pose's height, for skeletons without named feet


class SkeletonMatchError(InputError):
    """Roles of a skeleton that cannot be found by name; the message lists the missing ones."""


# ---------------------------------------------------------------------------------------------------
# roles
# ---------------------------------------------------------------------------------------------------

def default_bones(roles=MANIFEST_ROLES) -> dict[str, str]:
    """``{role: LAFAN1 name}`` of ``roles`` (a fresh dict: the manifest's default ``bones``)."""
    return {r: DEFAULT_BONES[r] for r in roles}


def bones_with_defaults(bones: dict[str, str] | None = None) -> dict[str, str]:
    """A bones table (role -> joint name) completed with the LAFAN1 names of the roles it does not name."""
    return {**DEFAULT_BONES, **(bones or {})}


def joint_of_role(names, bones: dict[str, str] | None, role: str) -> int | None:
    """Index of ``role``'s joint by exact name (``bones``, else :data:`DEFAULT_BONES`); None when absent."""
    name = bones_with_defaults(bones).get(role)
    names = list(names)
    return names.index(name) if name in names else None


def normalize_name(name: str) -> str:
    """``mixamorig:Left_Hand`` -> ``lefthand``: the form :data:`ROLE_SYNONYMS` lists."""
    name = str(name).rsplit(":", 1)[-1]
    return re.sub(r"[^a-z0-9]", "", name.lower())


def roles_by_synonyms(names, roles=tuple(ROLE_SYNONYMS)) -> dict[str, int]:
    """Index of each of ``roles`` found by name (the first synonym that some joint has wins); roles with no
    match are left out."""
    normalized = [normalize_name(n) for n in names]
    out = {}
    for role in roles:
        hit = next((i for syn in ROLE_SYNONYMS[role] for i, n in enumerate(normalized) if n == syn), None)
        if hit is not None:
            out[role] = hit
    return out


def missing_roles_error(missing, path="") -> SkeletonMatchError:
    """The one-line error for roles not found by name, with a few accepted names of each."""
    accepted = "; ".join(f"{k}: {', '.join(ROLE_SYNONYMS[k][:3])}" for k in missing if k in ROLE_SYNONYMS)
    return SkeletonMatchError(f"{path}: cannot match the key joints {', '.join(missing)} by name "
                              f"(accepted names, e.g. {accepted})")


def match_roles(names, roles, path="") -> dict[str, int]:
    """:func:`roles_by_synonyms` of ``roles``, in that order; raises :class:`SkeletonMatchError` naming
    ``path`` and every role it could not find."""
    found = roles_by_synonyms(names, roles)
    missing = [r for r in roles if r not in found]
    if missing:
        raise missing_roles_error(missing, path)
    return {r: found[r] for r in roles}


def find_toe(names, parents, foot: int) -> int | None:
    """A foot's toe joint: a child named like a toe, else its only child; None when it has none."""
    kids = children(parents, foot)
    for k in kids:
        if "toe" in str(names[k]).lower():
            return k
    return kids[0] if len(kids) == 1 else None


# ---------------------------------------------------------------------------------------------------
# the tree (parents before children, -1 for a root)
# ---------------------------------------------------------------------------------------------------

def children(parents, j: int) -> list[int]:
    """The joints whose parent is ``j``, in index order."""
    return [k for k in range(len(parents)) if int(parents[k]) == j]


def ancestors(parents, j: int) -> list[int]:
    """Joints from ``j``'s parent up to the root, nearest first."""
    out = []
    p = int(parents[j])
    while p >= 0:
        out.append(p)
        p = int(parents[p])
    return out


def subtree(parents, joints) -> list[int]:
    """``joints`` (one index or several) and all their descendants, in index (topological) order."""
    inside = {int(joints)} if np.ndim(joints) == 0 else {int(j) for j in joints}
    for j, pj in enumerate(parents):
        if pj in inside:
            inside.add(j)
    return sorted(inside)


def chain(parents, top: int, bottom: int) -> list[int]:
    """The joints from ``bottom`` up to ``top`` (both included), bottom first; raises ValueError when
    ``top`` is not above ``bottom``."""
    up = [bottom] + ancestors(parents, bottom)
    if top not in up:
        raise ValueError(f"joint {top} is not an ancestor of joint {bottom}")
    return up[:up.index(top) + 1]


def rest_positions(parents, offsets) -> np.ndarray:
    """(J, 3) global joint positions of the rest pose (offsets summed down the tree), in the offsets' unit."""
    offsets = np.asarray(offsets, dtype=np.float64).reshape(-1, 3)
    pos = offsets.copy()
    for j, p in enumerate(parents):
        if p >= 0:
            pos[j] = pos[p] + offsets[j]
    return pos


# ---------------------------------------------------------------------------------------------------
# units
# ---------------------------------------------------------------------------------------------------

def leg_length(parents, offsets, roles: dict[str, int]) -> float:
    """Hip-to-ankle length (thigh bone + shank bone: the foot's and its parent's offsets), mean of the sides."""
    offsets = np.asarray(offsets, dtype=np.float64)
    return 0.5 * sum(float(np.linalg.norm(offsets[roles[f"{s}_foot"]]) +
                           np.linalg.norm(offsets[int(parents[roles[f"{s}_foot"]])])) for s in SIDES)


def guess_unit_scale(names, parents, offsets) -> float | None:
    """Metres per file unit of a skeleton: the one of :data:`UNIT_SCALES` that makes its hip-to-ankle length
    closest to a human's (:data:`HUMAN_LEG_M`), or, when its feet are not found by name, its rest pose's
    height closest to :data:`HUMAN_HEIGHT_M`. None when that length is zero (nothing to measure)."""
    parents = np.asarray(parents, dtype=np.int64)
    roles = roles_by_synonyms(names, ("left_foot", "right_foot"))
    if len(roles) == 2:
        size, human = leg_length(parents, offsets, roles), HUMAN_LEG_M
    else:
        size, human = float(np.ptp(rest_positions(parents, offsets)[:, 1])) if len(parents) else 0.0, HUMAN_HEIGHT_M
    if not size > 0:
        return None
    return min(UNIT_SCALES, key=lambda s: abs(np.log(size * s / human)))


# ---------------------------------------------------------------------------------------------------
# the skeleton
# ---------------------------------------------------------------------------------------------------

@dataclass(eq=False)
class Skeleton:
    """Joint ``names``, ``parents`` (J,), rest ``offsets`` (J, 3) in file units, ``unit_scale`` (metres per file
    unit) and ``roles`` (role -> joint index). Build it with :meth:`from_bones` (a manifest's or database's
    table, then synonyms) or :meth:`by_synonyms`."""

    names: list[str]
    parents: np.ndarray
    offsets: np.ndarray
    unit_scale: float = 1.0
    roles: dict[str, int] = field(default_factory=dict)

    def __post_init__(self):
        self.names = [str(n) for n in self.names]
        self.parents = np.asarray(self.parents, dtype=np.int64).reshape(-1)
        J = len(self.names)
        self.offsets = (np.zeros((J, 3)) if self.offsets is None
                        else np.asarray(self.offsets, dtype=np.float64).reshape(-1, 3))
        if self.parents.shape != (J,) or self.offsets.shape != (J, 3):
            raise ValueError(f"{J} names, {self.parents.shape[0]} parents and {self.offsets.shape[0]} offsets")

    @classmethod
    def from_bones(cls, names, parents, offsets=None, bones: dict[str, str] | None = None,
                   unit_scale: float = 1.0) -> Skeleton:
        """Roles from ``bones`` (role -> joint name; names the skeleton lacks are skipped), then from name
        synonyms for the roles it leaves out."""
        names = [str(n) for n in names]
        roles = {r: names.index(n) for r, n in (bones or {}).items() if n in names}
        found = roles_by_synonyms(names)
        return cls(names, parents, offsets, unit_scale, {**{r: j for r, j in found.items() if r not in roles}, **roles})

    @classmethod
    def by_synonyms(cls, names, parents, offsets=None, unit_scale: float | None = None) -> Skeleton:
        """Roles from name synonyms only; ``unit_scale`` guessed (:func:`guess_unit_scale`, else 1) when None."""
        if unit_scale is None:
            unit_scale = guess_unit_scale(names, parents, offsets) or 1.0
        return cls(names, parents, offsets, unit_scale, roles_by_synonyms(names))

    @property
    def n_joints(self) -> int:
        return len(self.names)

    @property
    def hips(self) -> int:
        """The hips joint (the root of the body; a database's simulation bone sits above it)."""
        return self.joint("hips")

    @property
    def offsets_m(self) -> np.ndarray:
        return self.offsets * self.unit_scale

    def joint(self, role_or_name: str) -> int:
        """Index of a role's joint, or of a joint by name; KeyError when neither."""
        if role_or_name in self.roles:
            return self.roles[role_or_name]
        if role_or_name in self.names:
            return self.names.index(role_or_name)
        raise KeyError(f"no joint or role {role_or_name!r} (roles: {', '.join(sorted(self.roles)) or 'none'})")

    def require(self, roles, path="") -> dict[str, int]:
        """``{role: joint}`` of ``roles``; raises :class:`SkeletonMatchError` naming every missing one."""
        missing = [r for r in roles if r not in self.roles]
        if missing:
            raise missing_roles_error(missing, path)
        return {r: self.roles[r] for r in roles}

    def children(self, j: int) -> list[int]:
        return children(self.parents, j)

    def ancestors(self, j: int) -> list[int]:
        return ancestors(self.parents, j)

    def subtree(self, joints) -> list[int]:
        return subtree(self.parents, joints)

    def chain(self, top: int, bottom: int) -> list[int]:
        return chain(self.parents, top, bottom)

    def find_toe(self, foot: int) -> int | None:
        return find_toe(self.names, self.parents, foot)


# ---------------------------------------------------------------------------------------------------
# body proportions
# ---------------------------------------------------------------------------------------------------

# (pattern on the lower-cased name, radius / height); the first match wins, so specific names
# come before the general ones ("forearm" before "arm", "upleg" before "leg", "hand_index" before "hand")
BODY_RADII_BY_NAME = (
    (r"^simulation$", 0.0),
    (r"finger|thumb|index|middle|ring|pinky|little", 0.007),
    (r"toe|ball", 0.017),
    (r"head|skull", 0.055),
    (r"neck", 0.034),
    (r"forearm|lowerarm|fore_arm|lower_arm|elbow|radius|ulna", 0.024),
    (r"hand|wrist", 0.021),
    (r"clavicle|collar|shoulder", 0.036),
    (r"upperarm|upper_arm|arm|humerus", 0.032),
    (r"upleg|up_leg|upperleg|upper_leg|thigh|femur|\bhip\b|(left|right|^l|^r)_?hip", 0.047),
    (r"foot|ankle", 0.022),
    (r"leg|knee|shin|calf|tibia", 0.032),
    (r"hips|pelvis|root", 0.056),
    (r"chest|spine\D*[2-9]|torso|thorax|upper_?back", 0.072),
    (r"spine|back|abdomen|belly|waist|lumbar", 0.064),
)


def body_radii(names) -> np.ndarray:
    """(J,) radius of each joint's body part as a fraction of the character's height, from what its name says
    (hips, spine, thigh, forearm... in the usual BVH namings: LAFAN1, CMU, Mixamo, SMPL-like); NaN where the
    name says nothing (a drawing sizes those from the tree). The database's ``Simulation`` bone gets 0."""
    out = np.full(len(names), np.nan)
    for j, name in enumerate(names):
        low = str(name).lower()
        out[j] = next((r for pattern, r in BODY_RADII_BY_NAME if re.search(pattern, low)), np.nan)
    return out

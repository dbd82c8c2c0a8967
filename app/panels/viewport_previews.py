"""The preview ghosts panels ask the 3D view for (``Actions.set_preview``: a database frame, a motion
search result): where each stands, beside the inspected character and facing its way, and its drawing."""
from __future__ import annotations

import numpy as np

from lmm import quat
from lmm.skeleton import body_radii

from .common import lighter
from .viewport_markers import MarkerBatch
from .viewport_scene import FEATURE_COLOR


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
            names = list(pose.names) if pose.names is not None else None
            sk = self.viewer.Skeleton(self.ctx, parents, color=pose.color, alpha=0.6, names=names,
                                      body_radii=None if names is None else body_radii(names), style=style,
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


class Previews:
    """The preview ghosts each owner (a panel key) asks for, drawn beside the inspected character of the
    displayed tick (``drawings``: made with GL)."""

    def __init__(self):
        self.requests: dict[str, tuple] = {}   # owner -> PreviewPose tuple
        self.version = 0                       # counts set calls (the picture changes with each)
        self.drawings: PreviewDrawings | None = None

    def set(self, owner: str, poses) -> None:
        """Show ``poses`` as ``owner``'s ghosts (replacing its earlier ones; an empty tuple removes them)."""
        if poses:
            self.requests[owner] = tuple(poses)
        else:
            self.requests.pop(owner, None)
        self.version += 1

    def poses(self, hidden=()) -> list:
        """The ghosts to draw: those of the owners whose window is not in ``hidden`` (a layout that
        hides the Database window takes its candidate ghost away; showing it again brings it back)."""
        return [p for owner in sorted(self.requests) if owner not in hidden for p in self.requests[owner]]

    def update(self, view, batch: MarkerBatch, style: str, shadow: bool, roots: list) -> list[dict]:
        """Place the ghosts at the displayed tick; returns what was drawn (see :meth:`PreviewDrawings.update`),
        the first ghost's root added to ``roots`` (which the camera keeps in view) when there are any."""
        poses = self.poses(view.hidden_windows)
        snap = view.snap() if poses else None
        if not poses:
            anchor_pos = anchor_rot = None     # nothing to place (the drawings hide what they showed)
        elif snap is not None:
            # the inspected character's place without its side-by-side shift: left of the first character
            anchor_pos = np.asarray(snap.simulation_position, np.float64)
            anchor_rot = np.asarray(snap.simulation_rotation, np.float64)
        else:
            anchor_pos, anchor_rot = np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0])
        drawn = self.drawings.update(poses, batch, anchor_pos, anchor_rot, style, shadow) if self.drawings else []
        if drawn and roots:   # the camera keeps the first ghost in view with the characters
            roots.append(np.asarray(drawn[0]["root"]))
        return drawn

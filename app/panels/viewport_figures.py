"""The figures the 3D view draws beside the two characters: the session's reference clip (played by time
to their left, or aligned with them at each tick's aligned frame while they follow it) and the simulated
ragdoll (:mod:`lmm.physics.ragdoll`), further left."""
from __future__ import annotations

import numpy as np

from lmm.skeleton import body_radii

SIDE_OFFSET_M = 1.6             # a figure's distance from the next one beside it
REFERENCE_COLOR = (0.7, 0.72, 0.75)


def left_of_characters(slots: int) -> np.ndarray:
    """The offset of the figure ``slots`` places to the left of the first character."""
    return np.array([-SIDE_OFFSET_M * slots, 0.0, 0.0])


class ReferenceFigure:
    """The reference clip the session holds (:attr:`app.session.Session.reference`), drawn."""

    def __init__(self):
        self.clip = None               # the app.reference_clip.ReferenceClip drawn, or None
        self.skeleton = None           # its viewer.Skeleton (made with GL)
        self.followed = None           # the lmm.follow.FollowedTake the characters follow, or None
        self.overlay = False           # a followed reference drawn over the inspected character

    @property
    def shown(self) -> bool:
        return self.clip is not None and self.skeleton is not None

    def set_clip(self, clip, viewer=None, gl=None, scene=None, style: str = "capsules", shadow: bool = True) -> None:
        """Draw ``clip`` (None: nothing) instead of the one before (without ``gl``: kept for later)."""
        if self.skeleton is not None:
            scene.remove(self.skeleton)
            self.skeleton.release()
            self.skeleton = None
        self.clip = clip
        if clip is not None and gl is not None:
            self.skeleton = viewer.Skeleton(gl, clip.parents, color=REFERENCE_COLOR, names=clip.names,
                                            body_radii=body_radii(clip.names), style=style, shadow=shadow,
                                            joint_radius=0.024, bone_radius=0.016)
            scene.add(self.skeleton)

    def pose(self, view, offset_of):
        """Where the reference is drawn for the displayed tick: ``(positions (J, 3), offset (3,), frame)``;
        frame -1 when it plays by time (not followed, or before the first tick). ``offset_of(name)``: a
        character's side-by-side shift."""
        tick = view.tick
        take = self.followed
        if take is not None and tick is not None:
            name = view.inspected if (view.inspected, "reference_frame") in tick.series else \
                next((n for n, k in tick.series if k == "reference_frame"), None)
            if name is not None:
                frame = int(tick.series[(name, "reference_frame")])
                off = offset_of(name) if self.overlay else left_of_characters(1)
                return take.positions[frame], off, frame
        t = tick.time_s if tick is not None else 0.0
        return self.clip.at(t), left_of_characters(1), -1

    def update(self, view, offset_of, drawn: dict, roots: list) -> None:
        """Place the reference at the displayed tick (what was placed into ``drawn``; a followed one's
        root into ``roots``, which the camera keeps in view)."""
        if not self.shown:
            return
        positions, off, frame = self.pose(view, offset_of)
        self.skeleton.update(positions + off)
        drawn["reference"] = {"frame": frame, "root": [float(x) for x in positions[0]],
                              "offset": [float(x) for x in off]}
        if frame >= 0:       # the camera keeps the reference in view with the characters
            drawn["reference"]["root_path"] = [float(x) for x in self.followed.root_at(view.tick_number)]
            roots.append(np.asarray(positions[0], np.float64) + off)


RAGDOLL_HELP = ("Draw the physics ragdoll: a simulated body (mujoco) that follows the inspected\n"
                "controller's pose with joint motors. Where it crouches or falls while the character\n"
                "runs upright, the pose asks more than its motors give: it is not the character.\n"
                "Off by default; drawn while the Physics window is open.")


def ragdoll_shown(show: dict, view) -> bool:
    """The ragdoll's figure is drawn when the 3D view's Ragdoll box is on or the Physics window (whose
    plots it explains) is shown; otherwise it is left out of the picture and the camera's framing."""
    return bool(show.get("ragdoll")) or "physics" not in view.hidden_windows


class RagdollFigure:
    """One controller's ragdoll, a third character beside the two."""

    def __init__(self, skeleton):
        self.skeleton = skeleton       # viewer.Skeleton of the database's skeleton
        skeleton.visible = False

    @staticmethod
    def pose(view, reference_shown: bool):
        """The ragdoll drawn at the displayed tick: ``(controller, positions (J, 3), offset (3,))``, or
        None. It stands to the left of the first character (further left when a reference stands there)."""
        tick = view.tick
        poses = tick.extra.get("ragdoll") if tick is not None else None
        if not poses:
            return None
        name = view.ragdoll.get("drawn", "mm")
        if name not in poses:
            name = next(iter(poses))
        return name, np.asarray(poses[name], np.float64), left_of_characters(2 if reference_shown else 1)

    def prepare(self, view, reference_shown: bool):
        """:meth:`pose` with the skeleton's pose worked out (numpy only: safe on the tick worker), or None."""
        drawn = self.pose(view, reference_shown)
        if drawn is None:
            return None
        name, positions, off = drawn
        return name, positions, off, self.skeleton.prepare(positions + off)

    def head(self, view, reference_shown: bool) -> tuple:
        """Where the ragdoll's label hangs: above its highest joint (plain floats)."""
        _, positions, off = self.pose(view, reference_shown)
        hx, hy, hz = positions[int(np.argmax(positions[:, 1]))].tolist()
        ox, oy, oz = off.tolist()
        return hx + ox, hy + oy + 0.25, hz + oz

    def update(self, view, reference_shown: bool, drawn: dict, roots: list, prepared=None, shown=True) -> None:
        """Draw the ragdoll of the view's tick (``shown`` False: the 3D view's Ragdoll box is off)."""
        sk = self.skeleton
        if prepared is not None and shown:
            name, positions, off, pose = prepared
        else:
            placed = self.pose(view, reference_shown) if shown else None
            if placed is None:
                sk.visible = False
                drawn["ragdoll"] = None
                return
            name, positions, off = placed
            pose = positions + off
        sk.visible = True
        sk.update(pose)
        roots.append(positions[0] + off)
        drawn["ragdoll"] = {"controller": name, "root": [float(x) for x in positions[0]],
                            "offset": [float(x) for x in off]}

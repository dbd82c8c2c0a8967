"""What the studio's commands (:mod:`app.studio_commands`) do to the simulation and the shell: replay
input, open and follow a reference clip, load presets and weights, reset, inspect a controller, record;
open dialogs, switch layouts, orbit the camera, quit.

:class:`SessionActions` is a part of :class:`app.studio.Studio`; it uses the studio's ``session``,
``playback``, ``errors``, ``viewport``, ``panels``, ``layouts``, ``dialogs`` and ``observer``. Each action
reports a bad file in the error dialog and returns False instead of raising.
"""
from __future__ import annotations


from lmm.factory import make_controller

from .reference_clip import load_reference_clip


class SessionActions:
    inspected = "mm"
    lmm_problem: str | None = None
    last_recording = ""            # what the last finished recording wrote, or why it wrote nothing
    reference_path: str | None = None   # the reference BVH drawn beside the characters
    reviewed = None                # the reopened session shown (app.review), or None: the live characters

    def open_session_file(self, path: str) -> bool:
        """Reopen a session: the timeline covers it whole, every panel shows the picked tick (app.review)."""
        from .review import open_recorded_session

        return open_recorded_session(self, path)

    def open_input(self, spec: str) -> bool:
        from lmm.data.inputs import InputError, open_input

        try:
            log = open_input(spec)
        except (InputError, OSError, ValueError) as e:
            self.errors.show("Input", str(e))
            return False
        self.session.replay(log)
        self._draw_followed(None)
        self.playback.go_live()
        return True

    def live_input(self) -> None:
        self.session.stop_replay()
        self._draw_followed(None)

    def _draw_followed(self, take) -> None:
        if getattr(self, "viewport", None) is not None:     # None before the UI is built (--input)
            self.viewport.set_followed(take)

    def reset_characters(self) -> None:
        self.session.reset()
        self.playback.go_live()

    def set_ragdoll(self, key: str, value) -> None:
        """A ragdoll setting: ``enabled`` / ``residual`` (bool, from the next tick) or ``drawn`` (the
        controller whose ragdoll the 3D view shows)."""
        r = self.session.ragdolls
        if r is None:
            return
        if key == "enabled":
            r.enabled = bool(value)
            if not r.enabled:
                r.reset()          # switched on again, each ragdoll starts on its controller's pose
        elif key == "residual":
            r.settings.residual = bool(value)
        elif key == "drawn":
            r.drawn = str(value)
        else:
            raise ValueError(f"unknown ragdoll setting {key!r}")

    def reset_ragdolls(self) -> None:
        """Every ragdoll back on its controller's pose (a fallen one stands again); the fall counts restart."""
        if self.session.ragdolls is not None:
            self.session.ragdolls.reset()

    def open_reference(self, path: str) -> bool:
        from lmm.data.bvh import BVHError

        try:
            clip = load_reference_clip(path)
        except (BVHError, OSError, EOFError, ValueError) as e:
            self.errors.show("Reference BVH", str(e) if str(path) in str(e) else f"{path}: {e}")
            return False
        except Exception as e:
            self.errors.show("Reference BVH", f"{path}: cannot load: {type(e).__name__}: {e}")
            return False
        following = self.session.following is not None
        self.session.reference = clip
        self.viewport.set_reference(clip)
        self.reference_path = str(path)
        if following:                 # follow the new reference instead of the old one
            self.follow_reference(True)
        return True

    def follow_reference(self, on: bool = True) -> bool:
        """Drive the characters by the reference's derived input from a reset, draw the reference aligned
        with them and judge their poses against it (:mod:`lmm.follow`); off: back to live input. A
        reference that cannot be followed is reported in one line and stays drawn."""
        from lmm.data.bvh import BVHError
        from lmm.errors import InputError
        from lmm.follow import follow_take

        s = self.session
        if not on:
            if s.following is not None:
                s.stop_replay()
            self._draw_followed(None)
            return True
        if self.reference_path is None:
            self.errors.show("Follow reference", "no reference BVH is loaded: open one first (Reference BVH...)")
            return False
        path = self.reference_path
        manifest = self._manifest()
        if manifest is None:
            self.errors.show("Follow reference", f"{path}: cannot follow: the database's manifest cannot be read")
            return False
        try:
            from lmm.data.motion_files import load_motion

            take = follow_take(load_motion(path), manifest, s.db.names, s.tuning, s.dt, path)
        except (BVHError, InputError, OSError, EOFError, ValueError) as e:
            self.errors.show("Follow reference", str(e) if str(path) in str(e) else f"{path}: {e}")
            return False
        s.follow(take)
        self._draw_followed(take)
        self.playback.go_live()
        return True

    def set_reference_overlay(self, overlay: bool) -> None:
        """Draw the reference over the inspected character (else to the left of the characters)."""
        self.viewport.reference_overlay = bool(overlay)

    def load_preset(self, path: str) -> bool:
        from lmm.tuning import TuningError

        try:
            self.panels["tuning"].load_preset(path)
        except (TuningError, OSError, ValueError) as e:
            self.errors.show("Tuning preset", str(e) if str(path) in str(e) else f"{path}: {e}")
            return False
        return True

    def save_preset(self, path: str) -> bool:
        try:
            self.session.tuning.save(path)
        except OSError as e:
            self.errors.show("Tuning preset", f"{path}: cannot write ({e.strerror})")
            return False
        return True

    def load_weights(self, path: str) -> bool:
        s = self.session
        try:
            controller = make_controller("lmm", s.db, s.features, s.tuning, weights=path)
        except Exception as e:
            self.errors.show("LMM weights", str(e) if str(path) in str(e) else f"{path}: {e}")
            return False
        s.controllers["lmm"] = controller
        self.lmm_problem = None
        s.start_latent_table(path)
        self.viewport.add_controller("lmm")
        self.reset_characters()
        return True

    def set_inspected(self, name: str) -> None:
        if name in self.session.controllers:
            self.inspected = name

    def start_recording(self, path: str, which) -> bool:
        """Record the chosen controllers (never over an earlier take: the session numbers the files)."""
        try:
            paths = self.session.start_recording(path, tuple(which))
        except (OSError, ValueError) as e:
            self.errors.show("Recording", f"{path}: {e}")
            return False
        self.last_recording = "recording to " + ", ".join(p.name for p in paths.values())
        self.observer.recording_started(self.frame_index, paths)
        return True

    def stop_recording(self) -> None:
        try:
            result = self.session.stop_recording()
        except Exception as e:
            self.errors.show("Recording", f"cannot finish the recording: {e}")
            return
        self.last_recording = result.message
        self.observer.recording_stopped(self.frame_index, result)

    # -- the shell: dialogs, layouts, camera, previews, quit -------------------------------------
    def open_dialog(self, kind: str) -> None:
        self.dialogs.open(kind, self.panels["recording"].path() if kind == "record" else None)

    def switch_layout(self, name_or_path: str) -> bool:
        ok = self.layouts.switch(name_or_path, self.frame_index)
        self.menu.sync_window_checks()
        self._hidden = tuple(self.layouts.hidden())     # at once: the ghosts of hidden windows go with them
        return ok

    def orbit_camera(self, d_azimuth: float) -> None:
        """The input layer owns the camera azimuth (sticks and keys are camera relative)."""
        if self.input is not None:
            self.input.add_camera_orbit(d_azimuth)

    def quit(self) -> None:
        self.running = False

    def preview_database_frame(self, frame: int) -> None:
        """A clicked search candidate: the Database panel previews that frame (its window is shown)."""
        panel = self.panels.get("database")
        if panel is not None:
            self.layouts.show_window("database", True)
            self._hidden = tuple(self.layouts.hidden())     # its ghost is drawn from this frame on
            panel.show_frame(int(frame))

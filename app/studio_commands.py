"""The studio's commands: the one list of what a user can do (menus, shortcuts, test scripts, panels).

Ids are what a test script's ``"do"`` names (``{"frame": 30, "do": "scrub", "back": 20}``) and what a
session log records; a script action's other keys are the command's keyword arguments. Each callable
reaches the studio's parts when it runs (the panels and the 3D view exist only after the window is
built), so the list is registered once, when the studio is made.
"""
from __future__ import annotations

from .command_registry import ANY_ARGS, CommandRegistry
from .panels.common import window_tag
from .branch_view import BranchView
from .scripting import write_rects
from .why_not_probe import ProbeUnavailable, TickProbe, explanation_lines

#: file dialogs with a command each: (kind of app.dialogs.DIALOGS, label, menu, menu section)
DIALOG_COMMANDS = (("input", "Replay input CSV...", "File", 0), ("reference", "Open reference BVH...", "File", 0),
                   ("session", "Open session...", "File", 0),
                   ("preset_load", "Load tuning preset...", "File", 1),
                   ("preset_save", "Save tuning preset...", "File", 1),
                   ("weights", "Load LMM weights...", "File", 1), ("record", "Record to...", "", 0),
                   ("layout_load", "Load layout file...", "Layout", 1),
                   ("layout_save", "Save layout as...", "Layout", 1))


def register_studio_commands(reg: CommandRegistry, s) -> CommandRegistry:
    """Register every command on ``reg``; ``s`` is the :class:`app.studio.Studio` they act on."""
    add = reg.add
    # -- playback: the displayed tick ------------------------------------------------------------
    add("pause", "Pause", lambda: s.playback.pause())
    add("resume", "Play", lambda: s.playback.resume())
    add("toggle_pause", "Pause / play", lambda: s.playback.toggle_pause(), shortcut="Space", help="pause / play")
    add("step", "Step", lambda n=1: s.playback.step(int(n)), args=("n",))
    add("step_back", "Step back", lambda: s.playback.step(-1), shortcut=",", help="step back (paused)")
    add("step_forward", "Step forward", lambda: s.playback.step(1), shortcut=".", help="step forward (paused)")
    add("scrub", "Show tick", lambda tick=None, back=None: s.playback.scrub_to(
        int(tick) if tick is not None else s.session.history.newest_tick - int(back)), args=("tick", "back"))
    add("live", "Back to live", lambda: s.playback.go_live(), shortcut="Home", help="back to live")
    # -- files ----------------------------------------------------------------------------------
    for kind, label, menu, section in DIALOG_COMMANDS:
        add(f"dialog_{kind}", label, lambda kind=kind: s.open_dialog(kind), menu=menu, section=section)
    add("open", "Open a file (as its dialog would)", lambda kind, path: s.dialogs.handle(kind, path),
        args=("kind", "path"))
    add("open_input", "Replay input", lambda spec: s.open_input(spec), args=("spec",))
    add("open_session", "Reopen a session", lambda path: s.open_session_file(path), args=("path",))
    add("live_input", "Live input", lambda: s.live_input())
    add("reset_characters", "Reset characters", lambda: s.reset_characters(), menu="File", section=2)
    add("quit", "Quit", lambda: s.quit(), menu="File", section=2)
    # -- edit: tuning changes (app.undo) -------------------------------------------------------------
    add("undo", "Undo tuning change", lambda: s.session.undo.undo(), shortcut="Ctrl+Z", menu="Edit",
        help="undo a tuning change")
    add("redo", "Redo tuning change", lambda: s.session.undo.redo(), shortcut="Ctrl+Shift+Z", menu="Edit",
        help="redo a tuning change")
    # -- characters, reference, recording, ragdolls --------------------------------------------------
    add("inspect", "Inspect controller", lambda controller: s.set_inspected(controller), args=("controller",))
    add("follow", "Follow the reference", lambda on=True, overlay=None: _follow(s, on, overlay),
        args=("on", "overlay"))
    add("reference_overlay", "Draw the reference over the character",
        lambda overlay: s.set_reference_overlay(bool(overlay)), args=("overlay",))
    add("record_start", "Start recording", lambda path, which=("mm", "lmm"): s.start_recording(path, tuple(which)),
        args=("path", "which"))
    add("record_stop", "Stop recording", lambda: s.stop_recording())
    add("ragdoll", "Ragdoll setting", lambda key=None, value=None, reset=False:
        s.reset_ragdolls() if reset else s.set_ragdoll(key, value), args=("key", "value", "reset"))
    add("reset_ragdolls", "Reset ragdolls", lambda: s.reset_ragdolls())
    # -- view: camera, windows, layouts, previews, messages ---------------------------------------------
    add("camera_follow", "Toggle camera follow", lambda: s.viewport.toggle_follow(), shortcut="F",
        help="toggle camera follow")
    add("orbit_camera", "Orbit the camera", lambda d_azimuth: s.orbit_camera(float(d_azimuth)), args=("d_azimuth",))
    add("layout", "Switch layout", lambda name: s.switch_layout(name), args=("name",))
    add("show", "Show window", lambda window, show=True: s.layouts.show_window(window, bool(show)),
        args=("window", "show"))
    add("window_size", "Resize a window", lambda window, width, height: s.dpg.configure_item(
        window_tag(window), width=int(width), height=int(height)), args=("window", "width", "height"))
    add("set_preview", "Preview ghosts", lambda owner, poses: s.viewport.set_preview(owner, poses),
        args=("owner", "poses"))
    add("preview_database_frame", "Preview a database frame", lambda frame: s.preview_database_frame(int(frame)),
        args=("frame",))
    add("show_error", "Show an error", lambda title, message: s.errors.show(title, message), args=("title", "message"))
    add("show_info", "Show a message", lambda title, message: s.errors.inform(title, message),
        args=("title", "message"))
    add("help", "Keys and mouse", lambda: s.menu.show_keys_help(), menu="Help")
    add("dismiss", "OK on the message shown", lambda: s.errors.dismiss())
    # -- panels' own controls --------------------------------------------------------------------
    add("set_tuning", "Set a tuning slider", lambda field, value, channel=None:
        s.panels["tuning"].set_field(field, value, channel), args=("field", "value", "channel"))
    add("sort", "Sort the candidates", lambda key, descending=False:
        s.panels["candidates"].set_sort(key, bool(descending)), args=("key", "descending"))
    add("search_view", "Show a tab of the Nearest Neighbour vs Projector panel (projector, channels)",
        lambda view: s.panels["search"].show_view(view), args=("view",))
    add("click_candidate", "Preview a candidate row", lambda row: s.panels["candidates"].click_row(int(row)),
        args=("row",))
    probe = TickProbe(s)
    add("why_not", "Why not this frame", lambda database_frame: _why_not(s, probe, int(database_frame)),
        args=("database_frame",))
    add("what_if", "What if (scratch tuning)", lambda field=None, value=None, channel=None, clear=False:
        _what_if(s, probe, field, value, channel, bool(clear)), args=("field", "value", "channel", "clear"))
    add("continuing_pose", "The continuing pose's cost at the shown search", lambda: probe.continuing())
    branch = BranchView(s, probe)
    add("branch_here", "Branch here (A/B)", lambda scratch=False: _branch(s, branch, bool(scratch)), menu="Edit",
        section=1, args=("scratch",))
    add("branch_clear", "Close the branch", lambda: branch.clear(), menu="Edit", section=1)
    add("branch_difference", "A vs B at the shown tick", lambda: branch.difference())
    add("database", "Database panel", lambda **a: s.panels["database"].run_command(a), args=ANY_ARGS)
    add("coverage", "Coverage panel", lambda mode=None, channel=None: _coverage(s.panels["coverage"], mode, channel),
        args=("mode", "channel"))
    add("motion_search", "Run a motion search", lambda **a: s.panels["motion_search"].run_script(a), args=ANY_ARGS)
    # -- test hooks (scripts and the state dump) -------------------------------------------------------
    add("screenshot", "Save a screenshot", lambda path: s.request_screenshot(path), args=("path",))
    add("key_down", "Hold a key", lambda key: s.script.keys.add(key), args=("key",))
    add("key_up", "Release a key", lambda key: s.script.keys.discard(key), args=("key",))
    add("capture", "Capture what the panels show", lambda label: s.script.captures.append(label), args=("label",))
    add("quit_when_exists", "Quit once a file exists", lambda path: s.script.quit_when_exists(path), args=("path",))
    add("write_rects", "Write item rectangles", lambda path, items: write_rects(s.dpg, path, items), args=("path", "items"))
    # the session log keeps the commands that change the motion (app.session_log.RECORDED_COMMANDS)
    reg.events.connect(lambda run: s.session.log.command(run) if getattr(s, "session", None) else None)
    return reg


def _follow(s, on, overlay) -> bool:
    ok = s.follow_reference(bool(on))
    if overlay is not None:
        s.panels["recording"].set_overlay(bool(overlay))
    return ok


def _coverage(panel, mode, channel) -> None:
    if mode is not None:
        panel.set_mode(mode)
    if channel is not None:
        panel.set_channel(channel)


def _why_not(s, probe, frame: int) -> dict | None:
    """Explain ``frame`` at the shown tick in the Search Candidates panel (a reason it cannot: one line)."""
    panel = s.panels["candidates"]
    if frame != panel.why_frame:                    # a new question (not the shown tick's refresh): show the answer
        s.layouts.show_window("candidates", True)
    try:
        why = probe.why_not(frame)
    except ProbeUnavailable as e:
        panel.show_why_not(frame, [str(e)])
        return None
    panel.show_why_not(frame, explanation_lines(why, s.session.features.names))
    return why


def _what_if(s, probe, field, value, channel, clear: bool) -> dict | None:
    """Edit the scratch tuning (or clear it) and show the shown tick's search re-ranked under it."""
    from lmm.errors import InputError

    panel = s.panels["candidates"]
    if clear:
        probe.clear()
        panel.show_what_if(None)
        return None
    try:
        if field is not None:
            probe.edit(field, value, channel)
        result = probe.what_if()
    except (ProbeUnavailable, InputError) as e:
        s.errors.show("What if", str(e))
        return None
    panel.show_what_if(result)
    return result


def _branch(s, branch, scratch: bool) -> dict | None:
    """Branch here (a reason it cannot, e.g. live: one line in the error dialog)."""
    try:
        return branch.branch_here(scratch)
    except ProbeUnavailable as e:
        s.errors.show("Branch here", str(e))
        return None

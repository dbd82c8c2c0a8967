"""A 10-minute studio session replayed exactly (issue 33's acceptance): the real studio under Xvfb records
``--minutes`` of simulated time while sliders move, and ``lmm-studio replay`` remakes its BVH files byte for byte.

    PYTHONPATH=. python bench/studio_session_10min.py [--minutes 10] [--drags 6] [--keep DIR]

The studio runs with ``--script`` (a fixed 60 Hz step per rendered frame, so the session's length is counted in
ticks, whatever the wall time on a loaded machine) on ``builtin:random:1`` with MM and LMM, and records both
from frame 30 for ``--minutes``. During the recording: ``--drags`` real mouse drags (xdotool) of the Simulation
and Speeds sliders that are on screen, 36 slider moves through the Tuning panel's widgets (``set_tuning``: the
widget's value set and its callback fired, the values of ``bench/sessions.py``), two resets, inputs switched to
the keyboard (held keys), to ``builtin:circle`` and back, and a few undo / redo. After it: the session file's
counts, then per controller ``lmm-studio replay take.lmmsession --record again_NAME.bvh --controller NAME``,
its fingerprint check and a byte-for-byte comparison with the studio's ``take_NAME.bvh``.
"""
from __future__ import annotations

import argparse
import filecmp
import json
import os
import random
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

RECORD_FROM = 30          # the frame the recording starts (one tick a frame)
RECTS_AT = 20             # the frame the slider rectangles are written


def slider_specs() -> list[dict]:
    """The plain float sliders of the panel's groups open at start, near its top (likely on screen)."""
    from app.panels.tuning import widget_specs

    return [s for s in widget_specs() if s["group"] in ("simulation", "speeds") and s["kind"] == "float"
            and s["channel"] is None]


def script_actions(folder: Path, ticks: int) -> tuple[list[dict], dict]:
    """The studio's timed actions for a recording of ``ticks`` ticks, and their counts by kind."""
    from app.panels.tuning import widget_tag
    from sessions import events

    end = RECORD_FROM + ticks
    # the slider moves of bench/sessions.py (each value differs from the one before), through the widgets
    moves = [{"frame": RECORD_FROM + e["tick"], "do": "set_tuning", "field": p["field"], "value": p["new"],
              **({"channel": p["channel"]} if "channel" in p else {})}
             for e in events(ticks)["events"] if e["kind"] == "tuning" for p in (e["payload"],)]

    def at(fraction: float) -> int:
        return RECORD_FROM + int(fraction * ticks)

    actions = [
        {"frame": RECTS_AT, "do": "write_rects", "path": str(folder / "rects.json"),
         "items": [widget_tag(s) for s in slider_specs()]},
        {"frame": RECORD_FROM, "do": "record_start", "path": str(folder / "take.bvh"), "which": ["mm", "lmm"]},
        {"frame": at(0.12), "do": "reset_characters"},
        {"frame": at(0.25), "do": "live_input"},
        {"frame": at(0.25) + 1, "do": "key_down", "key": "w"},
        {"frame": at(0.27), "do": "key_down", "key": "d"},
        {"frame": at(0.29), "do": "key_up", "key": "d"},
        {"frame": at(0.31), "do": "key_down", "key": "shift"},
        {"frame": at(0.33), "do": "key_up", "key": "shift"},
        {"frame": at(0.34), "do": "key_up", "key": "w"},
        {"frame": at(0.35), "do": "open_input", "spec": "builtin:circle"},
        {"frame": at(0.48), "do": "undo"}, {"frame": at(0.48) + 2, "do": "undo"}, {"frame": at(0.48) + 4, "do": "undo"},
        {"frame": at(0.50), "do": "redo"}, {"frame": at(0.50) + 2, "do": "redo"},
        {"frame": at(0.55), "do": "open_input", "spec": "builtin:random:1"},
        {"frame": at(0.70), "do": "reset_characters"},
        {"frame": at(0.85), "do": "undo"}, {"frame": at(0.86), "do": "redo"},
        {"frame": end, "do": "record_stop"},
    ]
    kinds: dict[str, int] = {}
    for a in moves + actions[1:]:
        kinds[a["do"]] = kinds.get(a["do"], 0) + 1
    return sorted(moves + actions, key=lambda a: a["frame"]), kinds


class Dragger(threading.Thread):
    """Real mouse drags of on-screen Tuning sliders once the studio wrote their rectangles (xdotool)."""

    def __init__(self, env: dict, rects: Path, drags: int, seed: int, size: tuple[int, int], avoid: set,
                 every_s: float):
        super().__init__(daemon=True)
        self.every_s = every_s              # wall seconds between drags
        self.avoid = avoid                  # fields the script moves too: a drag's changes are told apart
        self.env, self.rects, self.drags, self.rng, self.size = env, rects, drags, random.Random(seed), size
        self.done: list[tuple[str, float, float]] = []       # (slider, from fraction, to fraction)
        self.note = ""
        self.frame_w = 0.0                                   # the slider frames' width found (px)

    def xdo(self, *args):
        return subprocess.run(["xdotool", *map(str, args)], env=self.env, capture_output=True, text=True, timeout=30)

    def frame_width(self, win, rect) -> int:
        """The slider frame's width on screen: an item's rectangle holds the frame and its label (whose font
        the studio picks), so the frame is the run of its own background colour from the left edge (the
        value text and the grab are drawn inside it; the label after a gap of the window's colour)."""
        from PIL import ImageGrab

        geo = dict(kv.split("=", 1) for kv in self.xdo("getwindowgeometry", "--shell", win).stdout.split() if "=" in kv)
        ox, oy = int(geo["X"]), int(geo["Y"])
        x0, y0, x1, y1 = (int(v) for v in rect)
        shot = ImageGrab.grab(xdisplay=self.env["DISPLAY"]).convert("RGB")
        row = [shot.getpixel((ox + x, oy + y0 + 2)) for x in range(x0, x1)]   # above the value text
        bg = row[2]
        inside = [i for i, p in enumerate(row) if max(abs(p[c] - bg[c]) for c in range(3)) <= 6]
        return inside[-1] + 1 if inside else 0

    def run(self) -> None:
        found = self.xdo("search", "--sync", "--onlyvisible", "--name", "lmm-studio")
        if found.returncode or not found.stdout.split():
            self.note = f"no studio window: {found.stderr.strip()}"
            return
        win = found.stdout.split()[0]
        for _ in range(600):
            if self.rects.exists():
                break
            time.sleep(0.5)
        time.sleep(2.0)
        try:
            rects = json.loads(self.rects.read_text())
        except (OSError, ValueError) as e:
            self.note = f"no slider rectangles: {e}"
            return
        # the panel's top rows, inside the studio's window and in its upper half (no other panel covers them
        # in the default layout)
        w, h = self.size
        shown = sorted((k for k, (x0, y0, x1, y1) in rects.items()
                        if k[len("tun_"):] not in self.avoid and x1 - x0 > 40 and y1 > y0 and 0 <= x0 and x1 <= w
                        and 20 <= y0 and y1 <= h / 2), key=lambda k: rects[k][1])
        if not shown:
            self.note = "no Tuning slider on screen"
            return
        frame_w = self.frame_width(win, rects[shown[0]])
        self.frame_w = frame_w
        if frame_w < 30:
            self.note = f"the sliders are {frame_w:.0f} px wide: too narrow to drag (use a wider --width)"
            return
        self.xdo("windowfocus", "--sync", win)
        for i in range(self.drags):
            tag = shown[i % len(shown)]
            x0, y0, _, y1 = rects[tag]
            y = int((y0 + y1) / 2)
            a, b = self.rng.uniform(0.1, 0.45), self.rng.uniform(0.55, 0.9)
            if i % 2:
                a, b = b, a
            self.xdo("mousemove", "--window", win, int(x0 + a * frame_w), y)
            self.xdo("mousedown", 1)
            for f in (0.5, 1.0):
                time.sleep(0.4)
                self.xdo("mousemove", "--window", win, int(x0 + (a + f * (b - a)) * frame_w), y)
            time.sleep(0.4)
            self.xdo("mouseup", 1)
            self.done.append((tag, round(a, 3), round(b, 3)))
            time.sleep(self.every_s)


def session_counts(path: Path) -> dict:
    con = sqlite3.connect(path)
    try:
        out = {t: con.execute(f"SELECT count(*) FROM {t}").fetchone()[0] for t in ("inputs", "events", "fingerprints")}
        out["events_by_kind"] = dict(con.execute("SELECT kind, count(*) FROM events GROUP BY kind").fetchall())
        out["tuning_fields"] = dict(con.execute("SELECT json_extract(payload, '$.field'), count(*) FROM events "
                                                "WHERE kind = 'tuning' GROUP BY 1").fetchall())
        out["commands"] = [r[0] for r in con.execute(
            "SELECT json_extract(payload, '$.id') FROM events WHERE kind = 'command' ORDER BY seq")]
    finally:
        con.close()
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=10.0, help="simulated minutes recorded (60 ticks a second)")
    ap.add_argument("--drags", type=int, default=6, help="real mouse drags of Tuning sliders during the recording")
    ap.add_argument("--drag-every", type=float, default=120.0, help="wall seconds between two drags")
    ap.add_argument("--width", type=int, default=1600)
    ap.add_argument("--height", type=int, default=900)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--keep", help="keep the files in this folder (default: a temporary one, removed)")
    a = ap.parse_args()
    if a.drags and shutil.which("xdotool") is None:
        print("xdotool is not installed: no real drags (use --drags 0)")
        return 1
    from lmm.session.reader import open_session
    from viewer.xvfb import Xvfb

    ticks = int(round(a.minutes * 3600))
    folder = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="bench_studio_session_"))
    folder.mkdir(parents=True, exist_ok=True)
    actions, planned = script_actions(folder, ticks)
    (folder / "script.json").write_text(json.dumps({"actions": actions}))
    frames = RECORD_FROM + ticks + 30
    with Xvfb("1920x1080x24") as x:
        env = dict(os.environ, DISPLAY=x.display, PYTHONPATH=str(ROOT), LMM_STUDIO_CONFIG=str(folder / "cfg"),
                   LP_NUM_THREADS="0")
        cmd = [sys.executable, "-m", "app.cli", "--frames", str(frames), "--input", "builtin:random:1",
               "--width", str(a.width), "--height", str(a.height),
               "--render-scale", "0.25", "--samples", "0", "--no-gamepads", "--no-save-layout",
               "--script", str(folder / "script.json")]
        print("studio:", " ".join(cmd[2:]), flush=True)
        t0 = time.perf_counter()
        proc = subprocess.Popen(cmd, cwd=folder, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        dragger = Dragger(env, folder / "rects.json", a.drags, a.seed, (a.width, a.height),
                          {x["field"] for x in actions if x["do"] == "set_tuning"}, a.drag_every)
        if a.drags:
            dragger.start()
        out, err = proc.communicate()
        studio_s = time.perf_counter() - t0
        dragger.join(timeout=1.0)
    print(f"studio: exit {proc.returncode}, {frames} frames in {studio_s:.0f} s wall "
          f"({studio_s / frames * 1e3:.1f} ms a frame); planned actions {planned}")
    if proc.returncode:
        print(err[-3000:])
        return 1
    print(f"real drags: {len(dragger.done)} {dragger.done} (slider frames {dragger.frame_w} px wide) {dragger.note}")
    session = folder / "take.lmmsession"
    f = open_session(session)
    counts = session_counts(session)
    dragged = {tag[len("tun_"):] for tag, _, _ in dragger.done}
    print(f"tuning changes from the drags (fields only the drags move): "
          f"{ {k: counts['tuning_fields'].get(k, 0) for k in sorted(dragged)} }")
    print(f"session: {session.stat().st_size / 1024:.0f} KiB, {f.ticks} ticks ({f.ticks / f.fps / 60:.2f} min), "
          f"recording from tick {f.recording_from} ({(f.ticks - f.recording_from) / f.fps / 60:.2f} min recorded), "
          f"closed {f.meta['closed']}; rows {counts}")
    f.close()
    ok = True
    for name in ("mm", "lmm"):
        again, take = folder / f"again_{name}.bvh", folder / f"take_{name}.bvh"
        t0 = time.perf_counter()
        r = subprocess.run([sys.executable, "-m", "app.cli", "replay", str(session), "--record", str(again),
                            "--controller", name], cwd=folder, env=env, capture_output=True, text=True)
        replay_s = time.perf_counter() - t0
        same = r.returncode == 0 and filecmp.cmp(take, again, shallow=False)
        match = "fingerprints match" in r.stdout
        ok &= same and match
        print(f"{name}: replay {replay_s:.1f} s (with process start), exit {r.returncode}: "
              f"{(r.stdout or r.stderr).strip()[-300:]}; studio BVH {take.stat().st_size / 2**20:.1f} MiB, "
              f"cmp {'IDENTICAL' if same else 'DIFFERENT'}", flush=True)
    if not a.keep:
        shutil.rmtree(folder, ignore_errors=True)
    print("ALL IDENTICAL, fingerprints match" if ok else "MISMATCH")
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())

"""A real mouse click (xdotool) on a Search Candidates row while the studio runs live previews the database
frame that row showed when it was clicked, though the table re-sorts at every search (here at every tick).

Which picture was on screen at a click is read from the clock: the test notes the monotonic time before
and after each mouse release (``xdotool mouseup``) and the studio's state dump notes, per frame, when
dearpygui's drawing began (``t - ms.ui``: events are taken at its start) and ended (``t``: the picture is
shown). A release made wholly between the end of frame n-1's drawing and the start of frame n's was on
picture n-1 and is taken by frame n, whose callback runs in frame n+1: the Database panel then holds row
r of frame n-1's rows. The first test asks that of enough such clicks, some of them where frame n's row
differed (there, the row's frame when the callback ran was not the one clicked: the bug before). The
second asks it of every release made while one picture stayed on screen, those taken during the next
frame's drawing included; it fails today (see its mark)."""
from __future__ import annotations

import random
import shutil
import time

import pytest

from studio_testutil import RealKeyStudio

pytestmark = pytest.mark.gui

ROW = 1                 # the second row, as the paused real-click test (test_database_panel.py)
CLICKS = 40
FIRST_CAPTURE, LAST_CAPTURE = 30, 2400


def _frames(dump) -> dict[int, dict]:
    """Per frame: when its drawing began and ended (perf_counter s), its rows' frames and the previewed
    database frame as captured after its panels updated."""
    out = {}
    for f in dump["frames"]:
        label = dump["labels"].get(f"f{f['frame']}")
        if label is None or "t" not in f:
            continue
        panels = label["panels"]
        out[f["frame"]] = {"end": f["t"], "start": f["t"] - f["ms"]["ui"] / 1e3,
                           "rows": [r["frame"] for r in panels["candidates"]["rows"]],
                           "preview": panels["database"].get("frame"), "origin": panels["database"].get("origin")}
    return out


def _picture_clicked(frames: dict[int, dict], t0: float, t1: float) -> int | None:
    """The frame n-1 whose picture a click made between ``t0`` and ``t1`` was on, when the click fell wholly
    between the end of its drawing and the start of frame n's; None otherwise."""
    for n in sorted(frames):
        prev, cur = frames.get(n - 1), frames[n]
        if prev is not None and prev["end"] < t0 and t1 < cur["start"]:
            return n - 1
    return None


@pytest.fixture(scope="module")
def live_clicks(xvfb_display, studio_cache, tmp_path_factory):
    """(frames, clicks): the per-frame record of :func:`_frames` and the (before, after) monotonic times of
    each mouse release on row ``ROW``, the studio live on builtin:circle and searching at every tick."""
    if shutil.which("xdotool") is None:
        pytest.skip("xdotool is not installed")
    tmp = tmp_path_factory.mktemp("live_click")
    rects = tmp / "rects.json"
    actions = [{"frame": 5, "do": "set_tuning", "field": "search_interval_s", "value": 0.0},
               {"frame": 10, "do": "show", "window": "database", "show": True},   # the layout settles first
               {"frame": 25, "do": "write_rects", "path": str(rects), "items": [f"cand_{ROW}_rank"]},
               *({"frame": n, "do": "capture", "label": f"f{n}"} for n in range(FIRST_CAPTURE, LAST_CAPTURE))]
    clicks = []
    with RealKeyStudio(tmp, xvfb_display, studio_cache, actions,
                       ["--layout", "default", "--input", "builtin:circle"]) as s:
        x0, y0, x1, y1 = s.rect(rects, f"cand_{ROW}_rank", settle_s=1.0)
        s.xdo("windowfocus", "--sync", s.win)
        s.xdo("mousemove", "--window", s.win, str(int(x0 + 6)), str(int((y0 + y1) / 2)))
        time.sleep(0.5)
        rng = random.Random(7)
        for _ in range(CLICKS):
            # a row is clicked on the release (ImGui's selectable); pressed for longer than a frame, as
            # a hand does, so that press and release are taken by different frames
            s.xdo("mousedown", "1")
            time.sleep(0.3)
            t0 = time.perf_counter()
            s.xdo("mouseup", "1")
            clicks.append((t0, time.perf_counter()))
            time.sleep(0.1 + 0.2 * rng.random())     # releases at every phase of the frames
        time.sleep(0.5)
    assert s.returncode == 0, s.stderr[-3000:]
    frames = _frames(s.dump())
    assert len(frames) > 100, "too few captured frames"
    return frames, clicks


def _preview_after(frames: dict[int, dict], shown: int, within: int = 6) -> int | None:
    """The database frame previewed by a click on picture ``shown``: the first change of the preview in the
    ``within`` frames after it (a click's callback runs two or three frames later), else the preview then
    (the same frame previewed again)."""
    later = [n for n in range(shown + 1, shown + within + 1) if n in frames]
    changed = [n for n in later if frames[n]["preview"] != frames[shown]["preview"]]
    return frames[changed[0]]["preview"] if changed else (frames[later[-1]]["preview"] if later else None)


def test_a_click_taken_at_the_next_frame_previews_the_row_clicked_xdotool(live_clicks):
    frames, clicks = live_clicks
    clean, discriminating = [], 0
    for t0, t1 in clicks:
        seen = _picture_clicked(frames, t0, t1)
        if seen is None or seen + 2 not in frames:
            continue
        clicked, callback = frames[seen], frames[seen + 2]
        assert callback["origin"] == "candidate", callback
        clean.append((clicked["rows"][ROW], callback["preview"]))
        discriminating += frames[seen + 1]["rows"][ROW] != clicked["rows"][ROW]
    assert len(clean) >= 3, f"only {len(clean)} of {CLICKS} clicks fell clear of a frame's drawing"
    assert discriminating >= 1, "the row never changed between the picture clicked and the next: nothing tested"
    assert [shown for shown, _ in clean] == [previewed for _, previewed in clean], clean


@pytest.mark.xfail(strict=True, reason="a release taken while the next frame is drawn (half of each frame at "
                                       "10 fps) previews the next frame's row: the rows change under the pointer")
def test_every_click_on_a_still_picture_previews_the_row_clicked_xdotool(live_clicks):
    """Every release made while one picture stayed on screen (none was shown during the ``xdotool`` call)
    previews the row that picture showed."""
    frames, clicks = live_clicks
    checked = []
    for t0, t1 in clicks:
        before = [n for n in frames if frames[n]["end"] < t0]
        if not before or max(before) != max(n for n in frames if frames[n]["end"] < t1):
            continue
        shown = max(before)
        checked.append((shown, frames[shown]["rows"][ROW], _preview_after(frames, shown)))
    assert len(checked) >= CLICKS // 2, f"only {len(checked)} of {CLICKS} releases were on a still picture"
    wrong = [c for c in checked if c[1] != c[2]]
    assert not wrong, f"{len(wrong)} of {len(checked)} (frame, row's database frame, previewed): {wrong}"

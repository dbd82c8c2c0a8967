"""app.layout_ini and the layout manager's native-crash guards (issue 36): nothing ImGui would trust
natively reaches it, a layout the studio cannot start with is never saved, and a start after a save that
died inside dearpygui opens with the default layout and says why."""
from __future__ import annotations

from pathlib import Path

import pytest

from app import layout_files
from app.layout_ini import IniError, check
from app.layouts import LayoutManager

ROOT = Path(__file__).resolve().parents[2]
WINDOW = "[Window][###10001]\nPos=10,20\nSize=300,200\nCollapsed=0\n"


def test_the_shipped_layouts_fit_the_grammar():
    for path in sorted((ROOT / "layouts").glob("*.ini")):
        check(path.read_text(encoding="utf-8"))


@pytest.mark.parametrize("extra,word", [
    ("[Table][0xD4BD52E9,2000000000]\nRefScale=15\n", "columns"),
    ("[Table][0xD4BD52E9,-7936]\n", "columns"),
    ("[Table][0xD4BD52E9,0]\n", "columns"),
    ("[Table][0xD4BD52E9,5]\nColumn 5  Width=10\n", "Column"),
    ("[Table][0xD4BD52E9,5]\nColumn 0  Width=10 Order=7\n", "Order"),
    ("[Table][0xD4BD52E9,5]\nColumn 0  Sort=9v\n", "Sort"),
    ("[Table][0xD4BD52E9,5]\nColumn 0  Weight=inf\n", "Weight"),
    ("[Table][0xD4BD52E9,5]\nColumn 0  Width=1_0\n", "Width"),
    ("[Table][0xD4BD52E9,5]\nRefScale=1e300\n", "RefScale"),
    ("[Docking][Data]\nDockNode ID=0x2 SizeRef=-1,5\n", "SizeRef"),
    ("[Docking][Data]\nDockNode ID=zz\n", "ID"),
    ("[Docking][Other]\n", "section"),
    ("[Viewport][0x1]\n", "section"),
])
def test_what_imgui_would_trust_is_refused_naming_the_line(extra, word):
    with pytest.raises(IniError, match=rf"line \d+: .*{word}"):
        check(WINDOW + "\n" + extra)


def _manager(reports):
    return LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))


def test_a_start_after_a_save_that_died_uses_the_default_and_says_why(tmp_path, monkeypatch):
    monkeypatch.setenv("LMM_STUDIO_CONFIG", str(tmp_path))
    user = layout_files.user_layout_path()
    user.write_text(WINDOW)
    (tmp_path / "layout.ini.saving").write_text("")
    reports = []
    m = _manager(reports)
    m.choose(None)
    m.close()
    assert m.layout.name == "default" and not user.exists() and (tmp_path / "layout.ini.bad").exists()
    assert len(reports) == 1 and "while saving it" in reports[0]
    assert not (tmp_path / "layout.ini.saving").exists()   # the next start is clean


class _Dpg:
    """What LayoutManager.save asks of dearpygui: ImGui's state written as ``ini``."""

    def __init__(self, ini):
        self.ini = ini

    def save_init_file(self, path):
        Path(path).write_text(self.ini)

    def does_item_exist(self, tag):
        return False

    def get_viewport_client_width(self):
        return 1600

    def get_viewport_client_height(self):
        return 900


def test_a_layout_no_start_could_use_is_never_saved(tmp_path):
    out = tmp_path / "layout.ini"
    out.write_text(WINDOW)
    reports = []
    m = _manager(reports)
    m.dpg = _Dpg(WINDOW + "\n[Table][0xD4BD52E9,-7936]\nRefScale=15\n")
    assert m.save(str(out)) is False
    assert out.read_text() == WINDOW and len(reports) == 1 and "not saved" in reports[0]
    m.dpg = _Dpg(WINDOW)
    assert m.save(str(out)) is True and layout_files.load(str(out)).windows
    assert sorted(p.name for p in tmp_path.iterdir()) == ["layout.ini"]   # no marker left

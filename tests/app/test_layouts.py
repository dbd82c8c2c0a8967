"""Layout files: the shipped layouts, broken or out-of-range files refused, user layouts set aside when they
broke a start, the hidden-windows note."""
import os
import pytest
from app import layout_files as layouts
from app.panels.menu import hidden_note
from lmm.tuning import Tuning


def test_shipped_layouts_hold_every_window_and_differ():
    rects = {}
    for name in layouts.builtin_names():
        lay = layouts.load(name)
        assert lay.path.name == f"{name}.ini"
        code = layouts.BUILTIN[name]
        assert lay.hidden == {k for k, v in code.items() if v is None}
        for key, rect in code.items():
            if rect is not None:
                assert tuple(lay.windows[key]["pos"]) == rect[:2], (name, key)
                assert tuple(lay.windows[key]["size"]) == rect[2:], (name, key)
        rects[name] = {k: tuple(v["pos"]) + tuple(v["size"]) for k, v in lay.windows.items() if k not in lay.hidden}
    assert rects["default"]["viewport"] != rects["compare"]["viewport"] != rects["tuning"]["viewport"]
    assert rects["compare"]["viewport"][2] > rects["default"]["viewport"][2]   # bigger 3D view to compare
    assert "search" in rects["compare"] and "tuning" not in rects["compare"]


def test_broken_layout_files_are_refused(tmp_path):
    cases = {"garbage.ini": "this is not an ini file\n", "empty.ini": "",
             "other.ini": "[Window][###424242]\nPos=1,2\nSize=3,4\n",
             "badpos.ini": "[Window][###10001]\nPos=a,b\nSize=3,4\n"}
    for name, text in cases.items():
        (tmp_path / name).write_text(text)
        with pytest.raises(layouts.LayoutError, match=name):
            layouts.load(str(tmp_path / name))
    (tmp_path / "bin.ini").write_bytes(b"\x00\x01\xff\xfe")
    with pytest.raises(layouts.LayoutError):
        layouts.load(str(tmp_path / "bin.ini"))
    with pytest.raises(layouts.LayoutError, match="no such layout"):
        layouts.load("no-such-layout")


def test_layout_helpers(tmp_path, monkeypatch):
    assert layouts.scaled((800, 22), (800, 878), (1600, 900), (1600, 900)) == ((800, 22), (800, 878))
    pos, size = layouts.scaled((800, 461), (800, 439), (1600, 900), (800, 461))
    assert pos[0] == 400 and size[0] == 400 and abs(pos[1] - 241) <= 1
    text = "[Window][###10001]\nPos=1,2\nSize=300,400\n" + layouts.extra_section(["stats"], (1280, 720))
    lay = layouts.parse(text)
    assert lay.hidden == {"stats"} and lay.reference_size == (1280, 720)
    assert "[LmmStudio]" not in layouts.strip_extra_section(text)
    monkeypatch.setenv("LMM_STUDIO_CONFIG", str(tmp_path / "cfg"))
    assert layouts.user_layout_path() == tmp_path / "cfg" / "layout.ini"
    monkeypatch.delenv("LMM_STUDIO_CONFIG")
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "xdg"))
    assert layouts.user_config_dir() == tmp_path / "xdg" / "lmm-studio"


@pytest.mark.parametrize("line", ["Pos=inf,0", "Pos=0,-inf", "Pos=nan,1", "Pos=1e400,2", "Pos=99999,0",
                                  "Size=100000,300", "Size=0,300", "Size=300,1e308", "Size=3", "Size=1,2,3"])
def test_layout_numbers_out_of_range_are_refused(tmp_path, line):
    path = tmp_path / "bad.ini"
    path.write_text(f"[Window][###10001]\nPos=10,20\nSize=300,200\n{line}\n")
    with pytest.raises(layouts.LayoutError, match=r"bad\.ini: line 4: (Pos|Size)") as e:
        layouts.load(str(path))
    assert "\n" not in str(e.value)


@pytest.mark.parametrize("value", ["inf,900", "0,0", "1600,nan", "100000,900", "-5,900"])
def test_layout_viewport_out_of_range_is_refused(tmp_path, value):
    path = tmp_path / "vp.ini"
    path.write_text("[Window][###10001]\nPos=10,20\nSize=300,200\n" + f"[LmmStudio][Layout]\nViewport={value}\n")
    with pytest.raises(layouts.LayoutError, match=r"vp\.ini: line 5: Viewport"):
        layouts.load(str(path))


def test_scaled_windows_never_exceed_the_viewport():
    pos, size = layouts.scaled((0, 22), (8192, 8192), (320, 240), (1600, 900))
    assert size[0] <= 1600 and size[1] <= 900


def test_a_broken_user_layout_is_set_aside_for_the_default(tmp_path, monkeypatch):
    from app.layouts import LayoutManager

    monkeypatch.setenv("LMM_STUDIO_CONFIG", str(tmp_path))
    user = tmp_path / "layout.ini"
    user.write_text("[Window][###10001]\nPos=inf,0\nSize=300,200\n")
    reports = []
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    ini = m.choose(None)
    assert m.layout.name == "default" and not user.exists() and (tmp_path / "layout.ini.bad").exists()
    assert len(reports) == 1 and "layout.ini" in reports[0] and "default" in reports[0]
    reports.clear()
    m.close()
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)                                      # the next start: no report, no loop
    assert m.layout.name == "default" and reports == []
    m.close()
    assert not os.path.exists(os.path.dirname(ini))   # the private working copy is gone


def test_a_user_layout_that_killed_its_start_is_set_aside(tmp_path, monkeypatch):
    from app.layouts import LayoutManager

    monkeypatch.setenv("LMM_STUDIO_CONFIG", str(tmp_path))
    user = tmp_path / "layout.ini"
    user.write_text((layouts.LAYOUT_DIR / "compare.ini").read_text())
    reports = []
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)
    assert m.layout.name == "user" and (tmp_path / "layout.ini.starting").exists() and reports == []
    m.close()                                           # ... and the studio died before started()
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)
    assert m.layout.name == "default" and (tmp_path / "layout.ini.bad").exists() and len(reports) == 1
    assert "did not finish" in reports[0]
    m.close()
    user.write_text((layouts.LAYOUT_DIR / "compare.ini").read_text())
    m = LayoutManager(None, lambda title, msg: reports.append(msg), (1600, 900))
    m.choose(None)
    m.started()                                         # a start that worked leaves no marker
    assert m.layout.name == "user" and not (tmp_path / "layout.ini.starting").exists()
    m.close()


def test_hidden_windows_note_names_them_and_the_menu():
    assert hidden_note(()) == ""
    note = hidden_note(("stats", "tuning"))
    assert "Tuning" in note and "Stats" in note and "Windows menu" in note

"""The one list of what a user can do (app.studio_commands through app.command_registry): scripts, menus,
shortcuts and panels name commands by id; each panel declares the commands it runs and the View fields it
reads."""
from __future__ import annotations

import ast
import dataclasses
import inspect
import json
import re
from pathlib import Path

import pytest

from app.command_registry import CommandRegistry, CommandRun
from app.input.keyboard import SHORTCUT_KEYS
from app.panels.base import View
from app.panels.catalog import dock_panels
from app.panels.menu import MenuBar, keys_help
from app.panels.viewport import ViewportPanel
from app.studio_commands import register_studio_commands

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def commands():
    return register_studio_commands(CommandRegistry(), object())   # callables reach the studio only when run


def test_a_command_runs_by_id_and_is_announced():
    reg = CommandRegistry()
    calls, runs = [], []
    reg.add("scrub", "Show tick", lambda tick=None: calls.append(tick) or tick, args=("tick",))
    reg.events.connect(runs.append)
    assert reg.run("scrub", tick=7) == 7 and reg.view(["scrub"]).scrub(9) == 9
    assert calls == [7, 9] and runs == [CommandRun("scrub", (), {"tick": 7}), CommandRun("scrub", (9,), {})]
    with pytest.raises(ValueError, match="takes no argument 'frame'"):
        reg.run("scrub", frame=3)
    with pytest.raises(ValueError, match="registered twice"):
        reg.add("scrub", "again", lambda: None)
    with pytest.raises(AttributeError, match="not among the panel's declared commands"):
        reg.view(["scrub"]).quit()


def test_every_script_verb_in_the_tests_and_docs_is_a_command(commands):
    """Scripts written before the registry keep working: each ``"do"`` names a registered id."""
    verbs = set()
    for path in [*ROOT.glob("tests/app/*.py"), *ROOT.glob("docs/images/*.json"), *ROOT.glob("bench/*.py")]:
        if path.name == Path(__file__).name:       # this file names a verb that is not one
            continue
        verbs |= set(re.findall(r'"do":\s*"([a-z_]+)"', path.read_text()))
    assert len(verbs) > 20 and verbs <= set(commands.ids()), verbs - set(commands.ids())


def test_menus_and_shortcuts_come_from_the_registry(commands):
    file_menu = [c.label for c in commands.in_menu("File")]
    assert file_menu[:2] == ["Replay input CSV...", "Open reference BVH..."] and file_menu[-1] == "Quit"
    assert [c.label for c in commands.in_menu("Help")] == ["Keys and mouse"]
    shortcuts = commands.shortcuts()
    assert set(shortcuts) <= set(SHORTCUT_KEYS) and shortcuts["Space"].id == "toggle_pause"
    text = keys_help(commands)
    assert all(f"  {key} " in text for key in shortcuts)


def _view_reads(cls) -> set[str]:
    return set(re.findall(r"\bview\.([a-z_]+)", inspect.getsource(cls)))


@pytest.mark.parametrize("cls", [*dock_panels(), MenuBar], ids=lambda c: c.__name__)
def test_each_panel_declares_its_commands_and_the_view_fields_it_reads(cls, commands):
    assert set(getattr(cls, "commands", ())) <= set(commands.ids()), cls.commands
    view_names = {f.name for f in dataclasses.fields(View)} | {n for n in vars(View) if not n.startswith("_")}
    declared = set(cls.reads)
    assert declared <= view_names, declared - view_names
    if cls is not ViewportPanel:     # the 3D view's parts read the view in their own modules
        assert _view_reads(cls) <= declared, _view_reads(cls) - declared


def test_the_studio_and_its_script_runner_do_not_import_each_other():
    for name in ("scripting", "studio_commands", "state_dump", "command_registry", "actions"):
        tree = ast.parse((ROOT / "app" / f"{name}.py").read_text())
        imported = {n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)}
        assert "studio" not in imported and "app.studio" not in imported, name


def test_a_script_runs_commands_with_its_keys_as_arguments(tmp_path):
    from app.scripting import Script

    reg, seen = CommandRegistry(), []
    reg.add("scrub", "Show tick", lambda tick=None, back=None: seen.append((tick, back)), args=("tick", "back"))
    reg.add("quit", "Quit", lambda: seen.append("quit"))
    path = tmp_path / "s.json"
    path.write_text(json.dumps({"actions": [{"frame": 2, "do": "scrub", "back": 5}, {"frame": 1, "do": "scrub",
                                                                                        "tick": 3}]}))
    script = Script.load(path)
    script.run(reg, 1)
    assert seen == [(3, None)]
    script.quit_when_exists(path)
    script.run(reg, 2)
    assert seen == [(3, None), "quit", (None, 5)]
    with pytest.raises(ValueError, match="unknown script action 'fly'"):
        Script([{"do": "fly"}]).run(reg, 0)

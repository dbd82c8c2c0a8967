"""``lmm-studio --tuning PRESET.json``: the studio starts from a preset (no display needed: the checks run
before any window, and the session is the engine side)."""
from __future__ import annotations

import json

import pytest

from app.cli import main as cli_main
from app.engine import StudioOptions, load_session


@pytest.mark.parametrize("text, says", [
    ('{"tag_bias": ', "not valid JSON (line 1"),
    ('{"stick_deadzone": 7}', "tuning field 'stick_deadzone': 7.0 is outside [0.0, 0.9]"),
    ('[1, 2]', "a tuning preset must be a JSON object"),
    ('{"no_such_field": 1}', "no_such_field"),
])
def test_a_broken_preset_is_one_line_before_any_window(tmp_path, monkeypatch, capsys, text, says):
    monkeypatch.setenv("DISPLAY", ":12345")    # a display that does not exist: no window may be opened
    preset = tmp_path / "broken.json"
    preset.write_text(text)
    assert cli_main(["--tuning", str(preset), "--frames", "1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"lmm-studio: error: {preset}") and says in err and "\n" not in err
    assert cli_main(["--tuning", str(tmp_path / "missing.json"), "--frames", "1"]) == 2
    assert "missing.json: no such tuning preset" in capsys.readouterr().err


def _session_from(preset, content: dict):
    """A studio session (MM only, no ragdolls) started from ``preset`` holding ``content``, and the errors
    it reported as (title, text) pairs."""
    preset.write_text(json.dumps(content))
    errors = []
    session, _ = load_session(StudioOptions(tuning=str(preset), lmm=False, physics=False),
                              lambda title, text: errors.append((title, text)))
    return session, errors


def test_the_session_starts_from_the_preset(tmp_path, db):
    session, errors = _session_from(tmp_path / "p.json", {"stick_deadzone": 0.35, "tag_bias": {"walk": 2.5}})
    assert not errors
    assert session.tuning.stick_deadzone == 0.35 and session.tuning.tag_bias["walk"] == 2.5
    assert all(c.tuning is session.tuning for c in session.controllers.values())
    assert session.tuning.simulation_velocity_halflife_s == 0.27     # what the preset leaves out: defaults


def test_a_preset_naming_another_databases_channel_is_reported(tmp_path, db):
    preset = tmp_path / "p.json"
    session, errors = _session_from(preset, {"stick_deadzone": 0.35, "feature_weights": {"no_such_channel": 1.0}})
    assert len(errors) == 1 and errors[0][0] == "Tuning preset"
    assert str(preset) in errors[0][1] and "no_such_channel" in errors[0][1] and "default tuning" in errors[0][1]
    assert session.tuning.stick_deadzone == 0.2                      # the defaults

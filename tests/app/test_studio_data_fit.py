"""The studio's menu bar says when the database cannot serve the tuning (lmm.data_fit): a database of
standing motion only, under the default run speeds, and the note going once the speed sliders ask for
what the data holds."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data_fit import SPEED_FIELDS

pytestmark = pytest.mark.gui


def standing_manifest(path: Path) -> Path:
    """The shipped manifest with only its 'idle' ranges (standing stretches: root speed p99 0.17 m/s)."""
    m = json.loads(Path(DEFAULT_MANIFEST).read_text())
    clips = []
    for clip in m["clips"]:
        idle = [r for r in clip["ranges"] if "idle" in r["tags"]]
        if idle:
            clips.append({**clip, "file": str(Path(DEFAULT_MANIFEST).parent / clip["file"]), "ranges": idle})
    m.update(name="standing_only", clips=clips)
    path.write_text(json.dumps(m))
    return path


def test_the_status_line_says_the_data_cannot_serve_the_run_speeds(run_studio, tmp_path):
    manifest = standing_manifest(tmp_path / "standing.json")
    shot = tmp_path / "slow_data.png"
    script = [{"frame": 20, "do": "capture", "label": "default_speeds"},
              {"frame": 20, "do": "screenshot", "path": str(shot)},
              *({"frame": 24, "do": "set_tuning", "field": f, "value": 0.2} for f in SPEED_FIELDS),
              {"frame": 30, "do": "capture", "label": "slow_speeds"}]
    r = run_studio("--frames", 34, "--no-lmm", "--manifest", manifest, "--input", "builtin:circle", script=script)
    assert r.rc == 0, r.stderr[-3000:]
    assert not r.dump["errors"], r.dump["errors"]
    before = r.dump["labels"]["default_speeds"]["panels"]["menu"]
    assert before["data_fit"].startswith("data: the tuning asks for up to 3.5 m/s, the database's root speed p99 is 0.")
    assert "standing_only does not cover" in before["data_fit_lines"] and "run_forward_speed 3.5" in before["data_fit_lines"]
    after = r.dump["labels"]["slow_speeds"]["panels"]["menu"]
    assert after["data_fit"] == "" and after["status"]   # the rest of the status line stays
    assert shot.exists()

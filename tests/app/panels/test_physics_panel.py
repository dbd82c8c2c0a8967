"""The Physics panel and the ragdoll in the 3D view: the real studio under Xvfb, with mujoco (the ragdolls
track MM and LMM, the panel plots them, the 3D view draws the chosen one beside the characters) and with
mujoco blocked (the studio runs, the panel says how to install it)."""
from __future__ import annotations

import numpy as np
import pytest

LAYOUT = """[Window][###10001]
Pos=0,22
Size=900,878

[Window][###10013]
Pos=900,22
Size=700,878

[LmmStudio][Layout]
Viewport=1600,900
Hidden=features,latent,search,candidates,tuning,stats,recording,timeline
"""
PHYSICS_RECT = (900, 22, 700, 878)


@pytest.mark.gui
def test_physics_panel_and_the_ragdoll(run_studio, tmp_path, lmm_weights):
    pytest.importorskip("mujoco")
    from PIL import Image

    layout = tmp_path / "physics.ini"
    layout.write_text(LAYOUT)
    shot = tmp_path / "physics.png"
    script = [{"frame": 200, "do": "capture", "label": "on"},
              {"frame": 201, "do": "ragdoll", "key": "residual", "value": False},
              {"frame": 201, "do": "ragdoll", "key": "drawn", "value": "lmm" if lmm_weights else "mm"},
              {"frame": 290, "do": "capture", "label": "off"},
              {"frame": 291, "do": "screenshot", "path": str(shot)}]
    args = ["--frames", 295, "--input", "builtin:circle", "--layout", layout]
    args += ["--weights", lmm_weights] if lmm_weights else ["--no-lmm"]
    r = run_studio(*args, script=script, timeout=300)
    assert r.rc == 0, r.stderr[-3000:]
    d = r.dump
    assert d["errors"] == []
    names = ["mm", "lmm"] if lmm_weights else ["mm"]
    on = d["labels"]["on"]["panels"]
    assert on["physics"]["status"] == "" and sorted(on["physics"]["controllers"]) == sorted(names)
    for name in names:
        c = on["physics"]["controllers"][name]
        # with the residual force the ragdoll follows its character closely and has not fallen
        assert 0.0 < c["mean_error_cm"] < 15.0 and c["falls"] == 0 and not c["fallen"]
        assert 0.0 < c["median_residual_bw"] < 3.0
    rag = on["viewport"]["ragdoll"]
    assert rag["controller"] == "mm"
    # drawn beside the characters, where its own simulation put it (near MM's root)
    assert rag["offset"][0] < on["viewport"]["offsets"]["mm"][0]
    assert np.linalg.norm(np.subtract(rag["root"], on["viewport"]["roots"]["mm"])[[0, 2]]) < 0.3
    assert "ragdoll" in on["viewport"]["labels"]
    off = d["labels"]["off"]["panels"]
    assert off["physics"]["settings"]["residual"] is False
    assert off["viewport"]["ragdoll"]["controller"] == names[-1]
    for name in names:
        res = off["physics"]["controllers"][name]["residual_bw"]
        assert res is None or np.isnan(res)                     # no residual force now (NaN: null in JSON)
    # the panel is drawn: plots with coloured curves
    img = np.asarray(Image.open(shot).convert("RGB"), np.float32)
    x, y, w, h = PHYSICS_RECT
    region = img[y + 60:y + h - 10, x + 10:x + w - 10]
    assert region.std() > 15.0
    import shutil, os
    if os.environ.get("LMM_STUDIO_KEEP_SCREENSHOT"):
        shutil.copy(shot, os.environ["LMM_STUDIO_KEEP_SCREENSHOT"])


@pytest.mark.gui
def test_without_mujoco_the_studio_runs_and_the_panel_says_how_to_install_it(run_studio, tmp_path):
    blocker = tmp_path / "block" / "mujoco"
    blocker.mkdir(parents=True)
    (blocker / "__init__.py").write_text("raise ModuleNotFoundError(\"No module named 'mujoco'\", name='mujoco')\n")
    layout = tmp_path / "physics.ini"
    layout.write_text(LAYOUT)
    from studio_testutil import ROOT

    script = [{"frame": 30, "do": "capture", "label": "end"}]
    r = run_studio("--frames", 35, "--input", "builtin:circle", "--layout", layout, "--no-lmm", script=script,
                   env_extra={"PYTHONPATH": f"{tmp_path / 'block'}:{ROOT}"})
    assert r.rc == 0, r.stderr[-3000:]
    panels = r.dump["labels"]["end"]["panels"]
    status = panels["physics"]["status"]
    assert "mujoco" in status and "pip install -e '.[physics]'" in status
    assert panels["viewport"]["ragdoll"] is None
    assert r.dump["errors"] == []

"""The runtime's imports: numpy only. Neither torch nor a plotting, GUI or GL package is imported by the
controllers, the factory, the tick loop, the database or the studio session, and nothing of
``lmm.offline`` (training, evaluation, export) is."""
import subprocess
import sys

RUNTIME = ("lmm.mm", "lmm.learned", "lmm.factory", "lmm.runner", "lmm.latents", "lmm.data.database", "app.session")
FORBIDDEN = ("torch", "matplotlib", "dearpygui", "moderngl", "lmm.offline")


def test_runtime_imports_no_offline_gui_or_gl_package():
    code = "\n".join([
        "import sys",
        *(f"import {m}" for m in RUNTIME),
        f"bad = sorted(m for m in sys.modules if m.split('.')[0] in {FORBIDDEN!r} or m.startswith('lmm.offline'))",
        "print('imported:', ' '.join(bad) if bad else '-')",
    ])
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip() == "imported: -", r.stdout


def test_a_studio_session_step_imports_nothing_offline(tmp_path):
    """Building the controllers, stepping a session and recording (lazy imports included)."""
    code = "\n".join([
        "import sys",
        "from lmm.data.database import load_or_build",
        "from lmm.features import build_features",
        "from lmm.factory import make_controllers",
        "from lmm.controller import InputState",
        "from lmm.tuning import Tuning",
        "from app.session import Session",
        "db, _ = load_or_build()",
        "f = build_features(db)",
        "t = Tuning()",
        "controllers, _ = make_controllers(db, f, t)",
        "s = Session(db, f, t, controllers)",
        f"s.start_recording({str(tmp_path / 'take.bvh')!r})",
        "[s.step(InputState(left_y=1.0)) for _ in range(10)]",
        "s.stop_recording()",
        "s.memory",
        f"bad = sorted(m for m in sys.modules if m.split('.')[0] in {FORBIDDEN!r} or m.startswith('lmm.offline'))",
        "print('imported:', ' '.join(bad) if bad else '-')",
    ])
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-1] == "imported: -", r.stdout

"""kill -9 of a recording studio (issue 33): every session file left behind reopens and replays, or is absent.

    PYTHONPATH=. python bench/studio_session_kills.py [--kills 20] [--seed 0]

The studio runs under Xvfb on builtin:circle with a script that starts recording at frame 0 and moves a
slider now and then; it is SIGKILLed ``--kills`` times at random moments after its window appears (a
quarter within the first 0.5 s). Each ``take.lmmsession`` left behind must open (``lmm.session.reader``)
and replay to its last committed tick with every fingerprint matching (``lmm-studio replay``), or not exist.
"""
from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))


def one_kill(folder: Path, delay: float, env: dict) -> tuple[str, str]:
    script = [{"frame": 0, "do": "record_start", "path": str(folder / "take.bvh"), "which": ["mm"]},
              *({"frame": 30 * i, "do": "set_tuning", "field": "run_forward_speed_m_s", "value": 2.0 + 0.1 * i}
                for i in range(1, 40))]
    (folder / "script.json").write_text(json.dumps({"actions": script}))
    p = subprocess.Popen([sys.executable, "-m", "app.cli", "--no-lmm", "--no-gamepads", "--input", "builtin:circle",
                          "--script", str(folder / "script.json"), "--frames", "100000"], cwd=folder, env=env,
                         stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    found = subprocess.run(["xdotool", "search", "--sync", "--onlyvisible", "--name", "lmm-studio"], env=env,
                           capture_output=True, timeout=120)
    if found.returncode:
        p.kill()
        return "no window", ""
    time.sleep(delay)
    p.send_signal(signal.SIGKILL)
    p.wait()
    session = folder / "take.lmmsession"
    if not session.exists():
        return "no file", ""
    from lmm.session.reader import open_session
    from lmm.errors import InputError

    try:
        f = open_session(session)
        state = f"{f.ticks} ticks (recording from {f.recording_from})"
        f.close()
    except InputError as e:
        return "NOT OPEN", str(e)
    r = subprocess.run([sys.executable, "-m", "app.cli", "replay", str(session)], cwd=ROOT, env=env,
                       capture_output=True, text=True)
    return state, (r.stdout.strip() if r.returncode == 0 else "FAILED " + r.stderr.strip())


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--kills", type=int, default=20)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args()
    from viewer.xvfb import Xvfb

    rng = random.Random(a.seed)
    rows = []
    with Xvfb() as x, tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, DISPLAY=x.display, PYTHONPATH=str(ROOT), LMM_STUDIO_CONFIG=str(Path(tmp) / "cfg"))
        for i in range(a.kills):
            delay = rng.uniform(0.0, 0.5) if i < a.kills // 4 else rng.uniform(0.5, 8.0)
            folder = Path(tmp) / f"k{i}"
            folder.mkdir()
            state, replay = one_kill(folder, delay, env)
            rows.append((delay, state, replay))
            print(f"  {delay:6.3f} s  {state:<34} {replay}", flush=True)
    bad = [r for r in rows if r[1] in ("NOT OPEN", "no window") or r[2].startswith("FAILED")]
    print(f"{len(rows) - len(bad)} of {len(rows)} left no file or a session that replays "
          f"({sum(r[1] == 'no file' for r in rows)} without a file)")


if __name__ == "__main__":
    main()

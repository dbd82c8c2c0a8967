"""SIGTERM always ends the studio (issue 36): its SIGTERM handler never ran while the main thread spun in
native code (ImGui's ini writer), for 16 CPU-minutes. app.watchdog kills such a process after a grace."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]

STUCK = ("import signal, sys, time\n"
         "from app import watchdog\n"
         "watchdog.arm(grace_s=float(sys.argv[1]))\n"
         "signal.signal(signal.SIGTERM, lambda s, f: print('handled', flush=True))\n"
         "print('ready', flush=True)\n"
         "sum(range(10**13))   # one C call: no Python handler runs until it returns (hours)\n")


def test_sigterm_ends_a_process_stuck_in_native_code():
    p = subprocess.Popen([sys.executable, "-c", STUCK, "1"], cwd=ROOT, stdout=subprocess.PIPE, text=True,
                         env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        assert p.stdout.readline().strip() == "ready"
        time.sleep(0.2)
        t0 = time.monotonic()
        p.send_signal(signal.SIGTERM)
        p.wait(timeout=20)
        assert p.returncode == -signal.SIGKILL and time.monotonic() - t0 < 10
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()


def test_the_watchdog_leaves_with_a_process_that_ends_normally():
    code = ("import sys\nfrom app import watchdog\nw = watchdog.arm(grace_s=1)\nprint(w.pid, flush=True)\n")
    r = subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True, timeout=30,
                       env={**os.environ, "PYTHONPATH": str(ROOT)})
    assert r.returncode == 0, r.stderr
    pid = int(r.stdout.strip())
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline and Path(f"/proc/{pid}").exists():
        if "Z" in Path(f"/proc/{pid}/stat").read_text().split()[2]:
            break   # ended, not yet reaped by its (gone) parent's init
        time.sleep(0.05)
    alive = Path(f"/proc/{pid}").exists() and "Z" not in Path(f"/proc/{pid}/stat").read_text().split()[2]
    assert not alive

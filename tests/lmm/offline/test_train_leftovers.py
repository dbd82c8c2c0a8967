"""A training killed with SIGKILL leaves nothing the next ``train`` does not remove (issue 36): the weights
archives and the loss log are written to temporaries named after the writing process
(``.NAME.PID.HEX.tmp``), and ``train`` removes those of processes that are gone from ``--out`` at its start."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

pytest.importorskip("torch")

ROOT = Path(__file__).resolve().parents[3]
TRAIN = [sys.executable, "-m", "app.cli", "train", "decompressor", "--log-every", "1", "--frames", "2000",
         "--threads", "1"]
FILES = {"default.npz", "compressor.npz", "training_log.csv"}


def test_a_killed_training_leaves_nothing_after_the_next_start(tmp_path):
    out = tmp_path / "weights"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen(TRAIN + ["--iterations", "5000", "--verbose", "--out", str(out)], stderr=subprocess.PIPE,
                         stdout=subprocess.DEVNULL, text=True, cwd=ROOT, env=env)
    try:
        for line in p.stderr:   # SIGKILL after the first iterations, while the loss log is being rewritten
            if line.startswith("[decompressor] it 3 "):
                p.send_signal(signal.SIGKILL)
                break
        p.communicate(timeout=60)
    finally:
        p.kill()
    assert p.returncode == -signal.SIGKILL
    # what a kill inside a save would leave (the killed process's id: it is gone), and one of a live process
    dead = [f".default.npz.{p.pid}.0123abcd.tmp", f".compressor.npz.{p.pid}.89abcdef.tmp",
            f".training_log.csv.{p.pid}.00ff00ff.tmp"]
    live = f".default.npz.{os.getpid()}.deadbeef.tmp"
    for name in dead + [live]:
        (out / name).write_bytes(b"half a file")
    assert not [n for n in os.listdir(out) if n.endswith(".tmp") and n not in dead + [live]], os.listdir(out)
    r = subprocess.run(TRAIN + ["--iterations", "2", "--quiet", "--out", str(out)], capture_output=True, text=True,
                       cwd=ROOT, env=env, timeout=300)
    assert r.returncode == 0, r.stderr
    assert set(os.listdir(out)) == FILES | {live}   # a running writer's temporary is not touched

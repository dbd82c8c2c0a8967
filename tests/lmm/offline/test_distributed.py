"""Training devices and the DistributedDataParallel smoke test: two CPU processes (gloo) under torchrun
train every stage of a tiny database, and rank 0 writes loadable networks."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

torch = pytest.importorskip("torch")

from lmm import DATA_DIR  # noqa: E402
from lmm.offline.distributed import DeviceError, Parallel, pick_device  # noqa: E402

ROOT = Path(__file__).resolve().parents[3]


def test_pick_device():
    assert pick_device("cpu") == torch.device("cpu")
    assert pick_device("auto").type == ("cuda" if torch.cuda.is_available() else "cpu")
    with pytest.raises(DeviceError, match="--device tpu"):
        pick_device("tpu")
    if not torch.cuda.is_available():
        with pytest.raises(DeviceError, match="CUDA is not available"):
            pick_device("cuda")


def test_rank_zero_keeps_the_seed():
    assert Parallel(torch.device("cpu")).seed(1234) == 1234
    assert Parallel(torch.device("cpu"), rank=1, world=2).seed(1234) != 1234


def _tiny_manifest(tmp_path: Path) -> Path:
    """One walking stretch of a shipped take (2 x 400 frames at 60 fps, mirrored)."""
    take = DATA_DIR / "lafan1" / "multipleActions1_subject1.bvh.gz"
    path = tmp_path / "tiny.json"
    path.write_text(json.dumps({"name": "tiny", "clips": [{"file": str(take), "ranges": [[1130, 1330]]}]}))
    return path


def test_ddp_smoke_two_cpu_processes(tmp_path):
    out = tmp_path / "weights"
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LMM_STUDIO_CACHE": str(tmp_path / "cache"),
           "OMP_NUM_THREADS": "1"}
    cmd = [sys.executable, "-m", "torch.distributed.run", "--standalone", "--nproc_per_node", "2",
           "-m", "app.cli", "train", "all", "--device", "cpu", "--manifest", str(_tiny_manifest(tmp_path)),
           "--iterations", "3", "--batch", "16", "--threads", "1", "--out", str(out), "--quiet",
           "--json", "-"]
    done = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "x 2 processes (DDP)" in done.stderr
    summary = json.loads(done.stdout[done.stdout.index("{"):])  # rank 0 alone prints it
    assert summary["processes"] == 2 and summary["device"] == "cpu"
    assert set(summary["final_loss"]) == {"decompressor", "stepper", "projector"}

    from lmm.data.build import load_or_build
    from lmm.features import build_features
    from lmm.learned import LMMNetworks
    import numpy as np

    db, _ = load_or_build(_tiny_manifest(tmp_path), cache_dir=tmp_path / "cache")
    nets = LMMNetworks.load(out / "default.npz", db, build_features(db))
    state = np.zeros(nets.n_features + nets.n_latent, np.float32)
    assert np.isfinite(nets.decompressor(state)).all()


def _train_cmd(tmp_path, *extra) -> tuple[list[str], dict]:
    env = {**os.environ, "PYTHONPATH": str(ROOT), "LMM_STUDIO_CACHE": str(tmp_path / "cache")}
    return [sys.executable, "-m", "app.cli", "train", "all", "--manifest", str(_tiny_manifest(tmp_path)),
            "--device", "cpu", "--out", str(tmp_path / "weights"), "--quiet", *extra], env


def test_workers_two_processes_share_each_batch(tmp_path):
    """``--workers 2`` (the default on two cores) starts two single-threaded DDP processes itself, each on
    half of every batch; rank 0 alone prints and writes."""
    cmd, env = _train_cmd(tmp_path, "--workers", "2", "--iterations", "3", "--batch", "16", "--json", "-")
    done = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "x 2 processes (DDP) sharing each batch" in done.stderr
    summary = json.loads(done.stdout[done.stdout.index("{"):])
    assert summary["processes"] == 2 and summary["threads"] == 1
    assert summary["batch_per_process"] == {"decompressor": 8, "stepper": 8, "projector": 8}
    assert done.stdout.count('"final_loss"') == 1
    assert (tmp_path / "weights" / "default.npz").is_file()


def test_workers_and_several_threads_is_one_line(tmp_path):
    cmd, env = _train_cmd(tmp_path, "--workers", "2", "--threads", "3")
    done = subprocess.run(cmd, env=env, cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 2 and done.stderr.strip().count("\n") == 0, done.stderr
    assert "--workers 2 runs one thread each" in done.stderr


def test_sigterm_stops_every_worker_with_one_line(tmp_path):
    import signal
    import time

    cmd, env = _train_cmd(tmp_path, "--workers", "2", "--iterations", "200000", "--batch", "16")
    cmd.remove("--quiet")
    log = tmp_path / "err.txt"
    with open(log, "w") as err:
        proc = subprocess.Popen(cmd, env=env, cwd=tmp_path, stdout=subprocess.DEVNULL, stderr=err)
        deadline = time.monotonic() + 240
        while "decompressor" not in log.read_text().split("->", 1)[-1] and time.monotonic() < deadline:
            time.sleep(0.5)                       # the progress line: the workers are training
        proc.send_signal(signal.SIGTERM)
        code = proc.wait(timeout=120)
    text = log.read_text()
    assert code != 0 and "stopped" in text.lower(), text[-2000:]
    assert "Traceback" not in text, text[-3000:]
    left = subprocess.run(["pgrep", "-f", str(tmp_path / "weights")], capture_output=True, text=True).stdout
    assert not left.strip(), f"workers still running: {left}"


def test_a_failing_worker_stops_the_others():
    from lmm.offline.distributed import _wait_all

    t0 = __import__("time").monotonic()
    procs = [subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]),
             subprocess.Popen([sys.executable, "-c", "raise SystemExit(3)"])]
    codes = _wait_all(procs)
    assert codes[1] == 3 and codes[0] != 0
    assert __import__("time").monotonic() - t0 < 30

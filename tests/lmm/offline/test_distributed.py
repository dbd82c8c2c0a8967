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

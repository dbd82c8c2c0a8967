"""Training data for the learned motion matching networks: every frame's decompressor targets (pose
vectors), character-space poses and normalised matching features as float32 tensors, prepared once with
numpy, and the windows of consecutive frames the loops draw their batches from.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
import torch

from lmm.features import Features
from lmm.nn import character_parents, character_space, pose_vectors


def robust_std(x: np.ndarray, floor: float = 1e-3) -> np.ndarray:
    return np.maximum(x.std(axis=0), floor).astype(np.float32)


def window_starts(db, window: int, frames: np.ndarray | None = None) -> np.ndarray:
    """Frames f such that f .. f + window - 1 all lie in f's range (and in ``frames`` when given)."""
    starts = []
    for a, b in zip(db.range_starts, db.range_stops):
        if b - a >= window:
            starts.append(np.arange(a, b - window + 1))
    out = np.concatenate(starts) if starts else np.zeros(0, np.int64)
    if frames is not None:
        keep = np.isin(out, frames) & np.isin(out + window - 1, frames)
        out = out[keep]
    return out.astype(np.int64)


@dataclass
class TrainingData:
    """Everything the loops need, as float32 tensors over all frames."""
    Y: torch.Tensor            # (N, P) pose vectors (decompressor targets)
    Q: torch.Tensor            # (N, 15 (J-1)) character space
    X: torch.Tensor            # (N, D) normalised matching features (the network's feature space)
    parents: np.ndarray        # (J-1,) character-space parents
    n_bones: int
    dt: float
    windows2: np.ndarray       # starts of 2-frame windows
    feature_mean: np.ndarray
    feature_inv_scale: np.ndarray
    frames: np.ndarray | None = None  # the subset of frames used (None: all)

    @property
    def compressor_input(self) -> torch.Tensor:
        return torch.cat([self.Y, self.Q], dim=1)

    def to(self, device) -> "TrainingData":
        """The same data with its tensors on ``device`` (itself when they are there already)."""
        device = torch.device(device)
        if self.X.device == device:
            return self
        return replace(self, Y=self.Y.to(device), Q=self.Q.to(device), X=self.X.to(device))


def prepare(db, features: Features, frames: np.ndarray | None = None) -> TrainingData:
    """Precompute targets and features once. ``frames`` restricts training windows to a subset (tests)."""
    Y = pose_vectors(db)
    Q = character_space(db)
    return TrainingData(
        Y=torch.from_numpy(Y), Q=torch.from_numpy(Q), X=torch.from_numpy(features.normalized.astype(np.float32)),
        parents=character_parents(db.parents), n_bones=db.n_bones, dt=db.dt,
        windows2=window_starts(db, 2, frames), feature_mean=features.mean.copy(),
        feature_inv_scale=features.inv_scale.copy(), frames=frames)


def window_starts_from(data: TrainingData, window: int) -> np.ndarray:
    """Window starts using the range layout remembered in ``data.windows2``' database (recomputed from 2-windows)."""
    w2 = data.windows2
    # a frame f starts a W-window when f, f+1, ..., f+W-2 all start 2-windows
    ok = np.zeros(int(data.Y.shape[0]) + window, bool)
    ok[w2] = True
    good = np.ones(len(w2), bool)
    for k in range(1, window - 1):
        good &= ok[w2 + k]
    return w2[good] if window > 1 else w2

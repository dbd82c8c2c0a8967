"""Training of the learned motion matching networks (torch; never imported by the runtime).

Three stages, as in the paper (Holden et al. 2020, Algorithms 1-3):

1. ``decompressor``: the compressor (training only) and the decompressor, trained jointly as an
   auto-encoder whose bottleneck is ``[matching features, latent]``; losses in local and character
   space (forward kinematics), their frame-to-frame changes, and latent regularisation.
2. ``stepper``: predicts the time derivative of ``[features, latent]``; trained by autoregressive rollout
   over a window of frames.
3. ``projector``: maps a (noisy) query to the ``[features, latent]`` of its exact nearest neighbour.

Data preparation is numpy over all frames, done once; the loops index float32 tensors.
"""
from __future__ import annotations

import csv
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F

from lmm.features import Features
from lmm.offline.distributed import Parallel
from lmm.offline.networks import MLPSpec, NormalizedMLP, default_specs
from lmm.nn import character_parents, character_space, pose_vector_size, pose_vector_slices, pose_vectors
from lmm.progress import Progress

NETWORKS = ("decompressor", "stepper", "projector")


# ---------------------------------------------------------------------------------------------
# data preparation (numpy)
# ---------------------------------------------------------------------------------------------

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


# ---------------------------------------------------------------------------------------------
# torch kinematics for the losses
# ---------------------------------------------------------------------------------------------

def gram_schmidt(xy: torch.Tensor) -> torch.Tensor:
    """2-axis (..., 3, 2) -> rotation matrices (..., 3, 3)."""
    a = F.normalize(xy[..., 0], dim=-1, eps=1e-8)
    b = xy[..., 1]
    b = F.normalize(b - (a * b).sum(-1, keepdim=True) * a, dim=-1, eps=1e-8)
    return torch.stack([a, b, torch.linalg.cross(a, b)], dim=-1)


def fk_torch(rot: torch.Tensor, pos: torch.Tensor, vel: torch.Tensor, ang: torch.Tensor, parents):
    """Forward kinematics with velocities on rotation matrices. Shapes (B, J, 3, 3) / (B, J, 3)."""
    g_rot, g_pos, g_vel, g_ang = [], [], [], []
    for j, p in enumerate(parents):
        if p < 0:
            g_rot.append(rot[:, j]); g_pos.append(pos[:, j]); g_vel.append(vel[:, j]); g_ang.append(ang[:, j])
        else:
            pr = g_rot[p]
            offset = (pr @ pos[:, j, :, None])[..., 0]
            g_rot.append(pr @ rot[:, j])
            g_pos.append(offset + g_pos[p])
            g_vel.append(g_vel[p] + (pr @ vel[:, j, :, None])[..., 0] + torch.linalg.cross(g_ang[p], offset))
            g_ang.append((pr @ ang[:, j, :, None])[..., 0] + g_ang[p])
    return (torch.stack(g_rot, 1), torch.stack(g_pos, 1), torch.stack(g_vel, 1), torch.stack(g_ang, 1))


# ---------------------------------------------------------------------------------------------
# settings, logging
# ---------------------------------------------------------------------------------------------

# loss weights from the reference (see shared notes); names are the CSV columns
DECOMPRESSOR_WEIGHTS = {
    "loc_pos": 75.0, "loc_rot": 10.0, "loc_vel": 10.0, "loc_angvel": 1.25, "root_vel": 2.0, "root_angvel": 2.0,
    "contacts": 2.0, "chr_pos": 15.0, "chr_rot": 5.0, "chr_vel": 2.0, "chr_angvel": 0.75,
    "pos_change": 10.0, "rot_change": 1.75, "chr_pos_change": 2.0, "chr_rot_change": 0.75,
    "latent_l1": 0.1, "latent_l2": 0.1, "latent_vel": 0.01,
}
STEPPER_WEIGHTS = {"features": 2.0, "latent": 7.5, "features_vel": 0.2, "latent_vel": 0.5}
# The projector's weights differ from the reference's (features 1.0, latent 5.0, distance 0.3): a larger
# features weight and the "cell" term (see train_projector for the measurements behind them).
PROJECTOR_WEIGHTS = {"features": 10.0, "latent": 5.0, "distance": 0.3, "cell": 100.0}


@dataclass
class StageSettings:
    iterations: int
    batch: int
    lr: float
    warmup: float = 0.02          # fraction of iterations with a linear lr ramp
    final_lr_fraction: float = 0.01  # cosine decay to lr * this
    weight_decay: float = 1e-3


@dataclass
class Recipe:
    """The training recipe. Defaults: the fast recipe measured to fit 45 minutes on 2 CPU cores."""
    decompressor: StageSettings = field(default_factory=lambda: StageSettings(3000, 512, 2e-3))
    stepper: StageSettings = field(default_factory=lambda: StageSettings(5000, 128, 2e-3))
    projector: StageSettings = field(default_factory=lambda: StageSettings(24000, 512, 2e-3))
    stepper_window: int = 20
    projector_noise: float = 0.5   # query noise level, x std of each feature (see noisy_queries)
    projector_neighbours: int = 16  # database neighbours per frame in the cell term (see train_projector)
    projector_margin: float = 0.1   # how far inside its nearest neighbour's cell a projection should land
    seed: int = 1234
    threads: int = 2
    latent: int = 32
    hidden: int = 512
    log_every: int = 200

    def to_dict(self) -> dict:
        return asdict(self)

    def stage(self, name: str) -> StageSettings:
        return getattr(self, name)


def make_optimizer(params, s: StageSettings):
    opt = torch.optim.AdamW(params, lr=s.lr, weight_decay=s.weight_decay, amsgrad=True)
    warm = max(int(s.warmup * s.iterations), 1)

    def factor(i: int) -> float:
        if i < warm:
            return (i + 1) / warm
        t = min((i - warm) / max(s.iterations - warm, 1), 1.0)
        return s.final_lr_fraction + (1.0 - s.final_lr_fraction) * 0.5 * (1.0 + math.cos(math.pi * t))

    return opt, torch.optim.lr_scheduler.LambdaLR(opt, factor)


class LossLog:
    """Collects per-iteration losses, prints a line every ``log_every`` iterations and writes a CSV."""

    def __init__(self, network: str, total: int, log_every: int, csv_path=None, stream=None, quiet=False):
        self.network = network
        self.log_every = max(int(log_every), 1)
        self.stream = stream if stream is not None else sys.stderr
        self.quiet = quiet
        self.rows: list[dict] = []
        self._acc: dict[str, float] = {}
        self._n = 0
        self.csv_path = Path(csv_path) if csv_path else None
        self.start = time.perf_counter()
        self.progress = Progress(total, label=network, stream=self.stream, enabled=not quiet)

    def add(self, iteration: int, lr: float, terms: dict[str, float]) -> None:
        for k, v in terms.items():
            self._acc[k] = self._acc.get(k, 0.0) + v
        self._n += 1
        total = terms["loss"]
        self.progress.update(1, postfix=f"loss {total:.4f}")
        if (iteration + 1) % self.log_every == 0 or iteration + 1 == self.progress.total:
            row = {"network": self.network, "iteration": iteration + 1,
                   "elapsed_s": round(time.perf_counter() - self.start, 2), "lr": lr}
            row.update({k: v / self._n for k, v in self._acc.items()})
            self.rows.append(row)
            self._acc, self._n = {}, 0
            if not self.quiet:
                terms_txt = " ".join(f"{k}={v:.4g}" for k, v in row.items() if k not in ("network", "iteration", "elapsed_s", "lr", "loss"))
                self.stream.write(f"[{self.network}] it {row['iteration']} loss {row['loss']:.5f} lr {lr:.2e} "
                                  f"{row['elapsed_s']:.0f}s | {terms_txt}\n")
                self.stream.flush()
            if self.csv_path:
                self._write_csv()

    def _write_csv(self) -> None:
        keys: list[str] = []
        for r in self.rows:
            keys += [k for k in r if k not in keys]
        existing = []
        if self.csv_path.exists():
            with open(self.csv_path, newline="") as f:
                existing = [r for r in csv.DictReader(f) if r.get("network") != self.network]
            for r in existing:
                keys += [k for k in r if k not in keys]
        self.csv_path.parent.mkdir(parents=True, exist_ok=True)
        tmp = self.csv_path.with_name(self.csv_path.name + ".tmp")
        with open(tmp, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=keys)
            w.writeheader()
            for r in existing + self.rows:
                w.writerow(r)
        tmp.replace(self.csv_path)

    def close(self) -> None:
        self.progress.close()

    @property
    def first_loss(self) -> float:
        return float(self.rows[0]["loss"]) if self.rows else float("nan")

    @property
    def last_loss(self) -> float:
        return float(self.rows[-1]["loss"]) if self.rows else float("nan")


def _seed(seed: int) -> np.random.Generator:
    torch.manual_seed(seed)
    return np.random.default_rng(seed)


# ---------------------------------------------------------------------------------------------
# stage 1: compressor + decompressor
# ---------------------------------------------------------------------------------------------

def make_autoencoder(data: TrainingData, latent: int = 32, hidden: int = 512):
    n_pose = pose_vector_size(data.n_bones)
    specs = default_specs(n_features=data.X.shape[1], n_latent=latent, n_pose=n_pose,
                          n_compressor_in=data.Y.shape[1] + data.Q.shape[1], hidden=hidden)
    compressor = NormalizedMLP(specs["compressor"])
    decompressor = NormalizedMLP(specs["decompressor"])
    c_in = data.compressor_input.numpy()
    compressor.set_normalization(in_mean=c_in.mean(0), in_std=robust_std(c_in))
    Y = data.Y.numpy()
    decompressor.set_normalization(out_mean=Y.mean(0), out_std=robust_std(Y, 1e-4))
    return compressor, decompressor


def decompressor_losses(y_hat: torch.Tensor, y: torch.Tensor, q: torch.Tensor, z: torch.Tensor,
                        data: TrainingData, pairs: int) -> dict[str, torch.Tensor]:
    """All loss terms for a batch of ``2 * pairs`` frames: rows [:pairs] are frames t, [pairs:] frames t+1."""
    s = pose_vector_slices(data.n_bones)
    j = data.n_bones - 1
    B = y.shape[0]
    dt = data.dt

    def parts(v):
        return (v[:, s["positions"]].reshape(B, j, 3), v[:, s["rotations"]].reshape(B, j, 3, 2),
                v[:, s["velocities"]].reshape(B, j, 3), v[:, s["angular_velocities"]].reshape(B, j, 3))

    p_pos, p_xy, p_vel, p_ang = parts(y_hat)
    t_pos, t_xy, t_vel, t_ang = parts(y)
    p_rot = gram_schmidt(p_xy)
    c_rot, c_pos, c_vel, c_ang = fk_torch(p_rot, p_pos, p_vel, p_ang, data.parents)
    n_chr = 3 * j
    tq_pos = q[:, :n_chr].reshape(B, j, 3)
    tq_xy = q[:, n_chr:3 * n_chr].reshape(B, j, 3, 2)
    tq_vel = q[:, 3 * n_chr:4 * n_chr].reshape(B, j, 3)
    tq_ang = q[:, 4 * n_chr:5 * n_chr].reshape(B, j, 3)
    p_lxy = p_rot[..., :2]
    c_xy = c_rot[..., :2]

    def change(a, b):  # L1 of the frame-to-frame velocity of a against that of b
        return torch.mean(torch.abs((a[pairs:] - a[:pairs]) / dt - (b[pairs:] - b[:pairs]) / dt))

    l1 = lambda a, b: torch.mean(torch.abs(a - b))  # noqa: E731
    return {
        "loc_pos": l1(p_pos, t_pos), "loc_rot": l1(p_lxy, t_xy), "loc_vel": l1(p_vel, t_vel),
        "loc_angvel": l1(p_ang, t_ang),
        "root_vel": l1(y_hat[:, s["root_velocity"]], y[:, s["root_velocity"]]),
        "root_angvel": l1(y_hat[:, s["root_angular_velocity"]], y[:, s["root_angular_velocity"]]),
        "contacts": l1(y_hat[:, s["contacts"]], y[:, s["contacts"]]),
        "chr_pos": l1(c_pos, tq_pos), "chr_rot": l1(c_xy, tq_xy), "chr_vel": l1(c_vel, tq_vel),
        "chr_angvel": l1(c_ang, tq_ang),
        "pos_change": change(p_pos, t_pos), "rot_change": change(p_lxy, t_xy),
        "chr_pos_change": change(c_pos, tq_pos), "chr_rot_change": change(c_xy, tq_xy),
        "latent_l1": torch.mean(torch.abs(z)), "latent_l2": torch.mean(z * z),
        "latent_vel": torch.mean(torch.abs((z[pairs:] - z[:pairs]) / dt)),
    }



def _optimise(loss, terms: dict, opt, sched, log, it: int) -> None:
    """One optimiser and schedule step, then the loss and its terms into the log."""
    opt.zero_grad(set_to_none=True)
    loss.backward()
    opt.step()
    sched.step()
    log.add(it, sched.get_last_lr()[0], {"loss": float(loss.detach()), **{k: float(v.detach()) for k, v in terms.items()}})

def train_decompressor(data: TrainingData, s: StageSettings, seed: int = 1234, latent: int = 32, hidden: int = 512,
                       log_every: int = 200, csv_path=None, quiet: bool = False, stream=None,
                       networks=None, checkpoint=None, par: Parallel | None = None):
    """Train compressor + decompressor jointly. Returns (compressor, decompressor, LossLog).
    ``par``: the device and the processes taking part (default: this process on the CPU)."""
    par = par or Parallel(torch.device("cpu"))
    rng = _seed(par.seed(seed))
    compressor, decompressor = networks or make_autoencoder(data, latent, hidden)
    run_c, run_d = par.wrap(compressor), par.wrap(decompressor)
    data = data.to(par.device)
    c_in = data.compressor_input
    params = list(compressor.parameters()) + list(decompressor.parameters())
    opt, sched = make_optimizer(params, s)
    log = LossLog("decompressor", s.iterations, log_every, csv_path if par.is_main else None, stream,
                  quiet or not par.is_main)
    starts = data.windows2
    for it in range(s.iterations):
        f0 = torch.from_numpy(starts[rng.integers(0, len(starts), s.batch)]).to(par.device)
        frames = torch.cat([f0, f0 + 1])
        z = run_c(c_in[frames])
        y_hat = run_d(torch.cat([data.X[frames], z], dim=1))
        terms = decompressor_losses(y_hat, data.Y[frames], data.Q[frames], z, data, s.batch)
        loss = sum(DECOMPRESSOR_WEIGHTS[k] * v for k, v in terms.items())
        _optimise(loss, terms, opt, sched, log, it)
        if checkpoint and par.is_main and (it + 1) % (log_every * 10) == 0:
            checkpoint(it + 1)
    log.close()
    return compressor, decompressor, log


@torch.no_grad()
def compute_latents(compressor: NormalizedMLP, data: TrainingData, chunk: int = 8192) -> torch.Tensor:
    """The latent of every frame, on the CPU (computed where the compressor is)."""
    device = next(compressor.parameters()).device
    c_in = data.compressor_input
    return torch.cat([compressor(c_in[i:i + chunk].to(device)).cpu() for i in range(0, c_in.shape[0], chunk)])


# ---------------------------------------------------------------------------------------------
# stage 2: stepper
# ---------------------------------------------------------------------------------------------

def make_stepper(data: TrainingData, Z: torch.Tensor, windows: np.ndarray, latent: int = 32, hidden: int = 512):
    S = torch.cat([data.X, Z], dim=1).numpy()
    spec = default_specs(n_features=data.X.shape[1], n_latent=Z.shape[1], hidden=hidden)["stepper"]
    stepper = NormalizedMLP(spec)
    d = (S[windows + 1] - S[windows]) / data.dt
    stepper.set_normalization(in_mean=S.mean(0), in_std=robust_std(S), out_mean=d.mean(0), out_std=robust_std(d))
    return stepper


def train_stepper(data: TrainingData, Z: torch.Tensor, s: StageSettings, window: int = 20, seed: int = 1234,
                  hidden: int = 512, log_every: int = 200, csv_path=None, quiet=False, stream=None, stepper=None,
                  log_name: str = "stepper", par: Parallel | None = None):
    par = par or Parallel(torch.device("cpu"))
    rng = _seed(par.seed(seed + 1))
    starts = window_starts_from(data, window)
    if stepper is None:
        stepper = make_stepper(data, Z, window_starts_from(data, 2), Z.shape[1], hidden)
    run = par.wrap(stepper)
    S = torch.cat([data.X, Z], dim=1).to(par.device)
    nx = data.X.shape[1]
    s_std = stepper.in_std
    d_std = stepper.out_std
    opt, sched = make_optimizer(stepper.parameters(), s)
    log = LossLog(log_name, s.iterations, log_every, csv_path if par.is_main else None, stream,
                  quiet or not par.is_main)
    offsets = torch.arange(window, device=par.device)
    for it in range(s.iterations):
        f0 = torch.from_numpy(starts[rng.integers(0, len(starts), s.batch)]).to(par.device)
        gt = S[f0[:, None] + offsets]                     # (B, W, 59)
        cur = gt[:, 0]
        preds = [cur]
        for _ in range(1, window):
            cur = cur + data.dt * run(cur)
            preds.append(cur)
        pred = torch.stack(preds, dim=1)
        err = torch.abs(pred[:, 1:] - gt[:, 1:]) / s_std
        verr = torch.abs((pred[:, 1:] - pred[:, :-1]) - (gt[:, 1:] - gt[:, :-1])) / data.dt / d_std
        terms = {"features": err[..., :nx].mean(), "latent": err[..., nx:].mean(),
                 "features_vel": verr[..., :nx].mean(), "latent_vel": verr[..., nx:].mean()}
        loss = sum(STEPPER_WEIGHTS[k] * v for k, v in terms.items())
        _optimise(loss, terms, opt, sched, log, it)
    log.close()
    return stepper, log


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


# ---------------------------------------------------------------------------------------------
# stage 3: projector
# ---------------------------------------------------------------------------------------------

def noisy_queries(X: torch.Tensor, frames: torch.Tensor, x_std: torch.Tensor, generator=None,
                  noise: float = 0.5) -> torch.Tensor:
    """query = x + noise * std * U(0, 1) * N(0, 1): per-sample level, per-dimension Gaussian direction.

    ``noise`` 0.5: the queries' distances to their nearest frame then match those of the queries motion
    matching makes at run time (measured on builtin:random:1 and circle: median 1.33 / 1.24 against
    1.41 here; 2.57 with noise 1.0)."""
    level = torch.rand(frames.shape[0], 1, generator=generator) * noise   # drawn on the (CPU) generator
    direction = torch.randn(frames.shape[0], X.shape[1], generator=generator)
    return X[frames] + x_std * level.to(X.device) * direction.to(X.device)


def augmented_frames(X: torch.Tensor) -> torch.Tensor:
    """``[-2 X, |x|^2]`` (N x D+1): one matmul with ``[q, 1]`` then gives ``|x|^2 - 2 q.x``, the squared
    distance less the per-query constant ``|q|^2``, which is all an argmin needs."""
    return torch.cat([-2.0 * X, (X * X).sum(1, keepdim=True)], dim=1).contiguous()


def nearest_neighbours(queries: torch.Tensor, X: torch.Tensor, chunk: int = 1024, aug: torch.Tensor | None = None):
    """Exact nearest neighbours (squared Euclidean) of each query among the rows of X: (indices, costs).

    Chunks of ``chunk`` frames keep the distance block in cache and take a row minimum per chunk; the
    winners' costs are then recomputed directly. About 5x faster than forming the full distance matrix
    (24 ms against 136 ms for 512 queries over 54,624 frames on 2 threads), which made this search, not
    the network, the projector's training cost."""
    if aug is None:
        aug = augmented_frames(X)
    qa = torch.cat([queries, torch.ones(queries.shape[0], 1, dtype=queries.dtype, device=queries.device)], dim=1)
    values, indices = [], []
    for a in range(0, aug.shape[0], chunk):
        v, i = (qa @ aug[a:a + chunk].T).min(dim=1)
        values.append(v)
        indices.append(i + a)
    best = torch.stack(values, 1).argmin(1, keepdim=True)
    best_i = torch.stack(indices, 1).gather(1, best)[:, 0]
    exact = ((queries - X[best_i]) ** 2).sum(1)
    return best_i, exact


#: Largest distance block :func:`frame_neighbours` forms on a CPU, in bytes: a 2048-row block over the
#: 501,918 frames of a full LAFAN1 download would take 4 GB (15 GB resident was measured), and smaller
#: blocks rank the same rows the same way (each row's neighbours depend on that row only).
CPU_DISTANCE_BLOCK_BYTES = 256 * 2 ** 20


def frame_neighbours(X: torch.Tensor, k: int, chunk: int = 2048, aug: torch.Tensor | None = None) -> torch.Tensor:
    """The ``k`` nearest other frames of every frame (N x k indices, nearest first). ``chunk`` rows at a
    time, fewer on a CPU where the block would pass :data:`CPU_DISTANCE_BLOCK_BYTES`."""
    if aug is None:
        aug = augmented_frames(X)
    n, d = X.shape
    k = min(k, n - 1)
    if X.device.type == "cpu":
        chunk = max(1, min(chunk, CPU_DISTANCE_BLOCK_BYTES // (X.element_size() * max(n, 1))))
    out = []
    for a in range(0, n, chunk):
        dist = X[a:a + chunk] @ aug[:, :d].T + aug[:, d]   # |x|^2 - 2 q.x, enough to rank
        rows = torch.arange(dist.shape[0], device=dist.device)
        dist[rows, rows + a] = float("inf")                  # not itself
        out.append(dist.topk(k, dim=1, largest=False).indices)
    return torch.cat(out)


def cell_violation(px: torch.Tensor, target: torch.Tensor, rivals: torch.Tensor, margin: float) -> torch.Tensor:
    """How far each projection ``px`` (B x D) falls short of lying ``margin`` inside its target frame's
    Voronoi cell, measured against each rival frame (B x k x D): the signed distance from ``px`` to the
    plane bisecting target and rival (positive on the target's side) is
    ``(|px - rival|^2 - |px - target|^2) / (2 |rival - target|)``; returns ``relu(margin - that)`` (B x k).

    This is what exact nearest-neighbour agreement asks for: the projection's nearest frame is the target
    exactly when it is on the target's side of every such plane. A feature L1 loss alone spends its
    effort on getting close on average and leaves many projections just across a neighbour's border."""
    gap = (rivals - target[:, None]).norm(dim=2).clamp_min(1e-6)
    signed = (((px[:, None] - rivals) ** 2).sum(2) - ((px - target) ** 2).sum(1, keepdim=True)) / (2.0 * gap)
    return torch.relu(margin - signed)


def make_projector(data: TrainingData, Z: torch.Tensor, hidden: int = 512, noise: float = 0.5, skip: bool = True,
                   seed: int = 1234):
    S = torch.cat([data.X, Z], dim=1).numpy()
    X = data.X.numpy()
    nx = X.shape[1]
    spec = default_specs(n_features=nx, n_latent=Z.shape[1], hidden=hidden, projector_skip=skip)["projector"]
    projector = NormalizedMLP(spec)
    out_mean, out_std = S.mean(0), robust_std(S)
    if skip:
        # the feature outputs are a correction added to the query: normalise them by the statistics of
        # (nearest frame - query) over a sample of training queries
        gen = torch.Generator().manual_seed(seed + 3)
        frames = torch.randint(0, X.shape[0], (8192,), generator=gen)
        q = noisy_queries(data.X, frames, data.X.std(0), gen, noise)
        idx, _ = nearest_neighbours(q, data.X)
        corr = (data.X[idx] - q).numpy()
        out_mean[:nx], out_std[:nx] = 0.0, robust_std(corr)
    # queries are database features plus noise: their std is somewhat above the features'
    projector.set_normalization(in_mean=X.mean(0), in_std=robust_std(X) * 1.15, out_mean=out_mean, out_std=out_std)
    return projector


def train_projector(data: TrainingData, Z: torch.Tensor, s: StageSettings, seed: int = 1234, hidden: int = 512,
                    log_every: int = 200, csv_path=None, quiet=False, stream=None, projector=None,
                    log_name: str = "projector", noise: float = 0.5, neighbours: int = 16, margin: float = 0.1,
                    weights: dict | None = None, skip: bool = True, par: Parallel | None = None):
    """Noisy queries, their exact nearest frames as targets (features and latent), L1 losses, the
    reference's distance term, and the cell term (:func:`cell_violation` against the target's
    ``neighbours`` nearest frames). The projector has a skip connection (features = query + correction).
    ``weights`` overrides :data:`PROJECTOR_WEIGHTS`; ``bench/projector_ablation.py`` varies it and ``skip``
    and measured the choice (table in ``lmm/data/weights/README.md``): the cell term trades feature
    accuracy for landing in the right cell, and too much of it collapses the projector to the identity."""
    par = par or Parallel(torch.device("cpu"))
    rng = _seed(par.seed(seed + 2))
    gen = torch.Generator().manual_seed(par.seed(seed + 2))
    if projector is None:
        projector = make_projector(data, Z, hidden, noise, skip=skip, seed=seed)
    run = par.wrap(projector)
    weights = {**PROJECTOR_WEIGHTS, **(weights or {})}
    X = data.X.to(par.device)
    nx = X.shape[1]
    S = torch.cat([X, Z.to(par.device)], dim=1)
    x_std = X.std(0)
    aug = augmented_frames(X)
    rivals = frame_neighbours(X, neighbours, aug=aug) if weights["cell"] > 0 and neighbours > 0 else None
    z_std = torch.from_numpy(robust_std(Z.numpy())).to(par.device)
    pool = data.frames if data.frames is not None else np.arange(X.shape[0])
    opt, sched = make_optimizer(projector.parameters(), s)
    log = LossLog(log_name, s.iterations, log_every, csv_path if par.is_main else None, stream,
                  quiet or not par.is_main)
    for it in range(s.iterations):
        f = torch.from_numpy(pool[rng.integers(0, len(pool), s.batch)]).to(par.device)
        q = noisy_queries(X, f, x_std, gen, noise)
        nn_i, nn_cost = nearest_neighbours(q, X, aug=aug)
        target = S[nn_i]
        pred = run(q)
        px = pred[:, :nx]
        p_cost = ((q - px) ** 2).sum(1)
        terms = {"features": torch.mean(torch.abs(px - target[:, :nx])),
                 "latent": torch.mean(torch.abs(pred[:, nx:] - target[:, nx:]) / z_std),
                 "distance": torch.mean(torch.abs(p_cost - nn_cost))}
        if rivals is not None:
            terms["cell"] = cell_violation(px, target[:, :nx], X[rivals[nn_i]], margin).mean()
        loss = sum(weights[k] * v for k, v in terms.items())
        _optimise(loss, terms, opt, sched, log, it)
    log.close()
    return projector, log


# ---------------------------------------------------------------------------------------------
# the pipeline: stages, weights files
# ---------------------------------------------------------------------------------------------

RUNTIME_FILE = "default.npz"
COMPRESSOR_FILE = "compressor.npz"
LOG_FILE = "training_log.csv"


def base_metadata(db, features: Features, latent: int) -> dict:
    return {
        "database_key": db.key, "database_name": db.name, "n_frames": db.n_frames,
        "feature_layout": features.layout_dicts(),
        "feature_mean": [float(v) for v in features.mean], "feature_inv_scale": [float(v) for v in features.inv_scale],
        "latent": latent, "n_bones": db.n_bones, "bone_names": list(db.names),
        "parents": [int(p) for p in db.parents], "pose_vector_size": pose_vector_size(db.n_bones),
    }


def _save_networks(path, nets: dict, metadata: dict, extra: dict | None = None):
    from lmm.data import weights as W
    arrays = {}
    for name, net in nets.items():
        arrays.update(net.to_arrays(name))
    meta = dict(metadata)
    meta["networks"] = {name: net.spec.to_dict() for name, net in nets.items()}
    meta.update(extra or {})
    return W.save(path, arrays, meta)


def _load_networks(path, names, db, features) -> tuple[dict, dict]:
    from lmm.data import weights as W
    wf = W.load(path, require=names, db_key=db.key, layout_dicts=features.layout_dicts())
    nets = {}
    for name in names:
        net = NormalizedMLP(MLPSpec.from_dict(wf.spec(name)))
        net.load_arrays(wf.arrays, name)
        nets[name] = net
    return nets, wf.metadata


def train_pipeline(db, features: Features, stages=NETWORKS, recipe: Recipe | None = None, out_dir="lmm-weights",
                   frames: np.ndarray | None = None, quiet: bool = False, stream=None, resume: bool = False,
                   par: Parallel | None = None) -> dict:
    """Train the given stages in order and write ``default.npz`` (decompressor, stepper, projector),
    ``compressor.npz`` and ``training_log.csv`` into ``out_dir``. Stages not trained are taken from
    the files already in ``out_dir``. ``resume``: stepper/projector start from the ones in ``out_dir``
    (a further schedule on top of a finished run) instead of from scratch. ``par``: the device and, under
    torchrun, the processes taking part (see :mod:`lmm.offline.distributed`; only rank 0 writes files).
    Returns a summary."""
    par = par or Parallel(torch.device("cpu"))
    recipe = recipe or Recipe()
    stream = stream if stream is not None else sys.stderr
    torch.set_num_threads(recipe.threads)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    runtime_path, comp_path, csv_path = out_dir / RUNTIME_FILE, out_dir / COMPRESSOR_FILE, out_dir / LOG_FILE
    t_all = time.perf_counter()
    t0 = time.perf_counter()
    data = prepare(db, features, frames)
    summary: dict = {"prepare_s": round(time.perf_counter() - t0, 2), "wall_s": {}, "final_loss": {}, "first_loss": {}}
    meta = base_metadata(db, features, recipe.latent)
    meta["recipe"] = recipe.to_dict()
    meta["seed"] = recipe.seed
    meta["torch_version"] = torch.__version__
    nets: dict[str, NormalizedMLP] = {}
    previous: dict = {}
    if "decompressor" not in stages:
        loaded, _ = _load_networks(comp_path, ["compressor"], db, features)
        nets.update(loaded)
    if runtime_path.exists():
        try:
            from lmm.data import weights as W
            prev = W.load(runtime_path, require=[], db_key=db.key, layout_dicts=features.layout_dicts())
            previous = dict(prev.metadata)
            keep = [n for n in NETWORKS if (n not in stages or (resume and n != "decompressor")) and n in prev.networks]
            loaded, _ = _load_networks(runtime_path, keep, db, features)
            nets.update(loaded)
        except Exception as e:  # noqa: BLE001 - a stale file is simply replaced
            stream.write(f"note: not reusing {runtime_path} ({e})\n")
    for needed in [n for n in NETWORKS if n not in stages]:
        if needed not in nets and any(NETWORKS.index(s) > NETWORKS.index(needed) for s in stages):
            if needed == "decompressor":
                raise FileNotFoundError(f"{runtime_path}: train the decompressor first (`lmm-studio train all`)")
    wall = dict(previous.get("wall_s", {}))

    def save_all(note: str = ""):
        if not par.is_main:
            return
        runtime = {n: nets[n] for n in NETWORKS if n in nets}
        extra = {"wall_s": wall, "note": note}
        if "compressor" in nets:
            _save_networks(comp_path, {"compressor": nets["compressor"]}, meta, extra)
            if runtime:
                z = compute_latents(nets["compressor"], data).numpy()
                extra["latent_mean"] = [float(v) for v in z.mean(0)]
                extra["latent_std"] = [float(v) for v in z.std(0)]
        if runtime:
            _save_networks(runtime_path, runtime, meta, extra)

    if "decompressor" in stages:
        s = recipe.decompressor
        t0 = time.perf_counter()
        torch.manual_seed(recipe.seed)  # the initial weights, too, follow the seed
        pair = make_autoencoder(data, recipe.latent, recipe.hidden)
        nets["compressor"], nets["decompressor"] = pair

        def checkpoint(it):
            save_all(f"checkpoint: decompressor at iteration {it}/{s.iterations}")

        _, _, log = train_decompressor(data, s, recipe.seed, recipe.latent, recipe.hidden, recipe.log_every,
                                       csv_path, quiet, stream, networks=pair,
                                       checkpoint=None if frames is not None else checkpoint, par=par)
        wall["decompressor"] = round(time.perf_counter() - t0, 1)
        summary["first_loss"]["decompressor"], summary["final_loss"]["decompressor"] = log.first_loss, log.last_loss
        save_all("after decompressor")
    Z = compute_latents(nets["compressor"], data)
    if "stepper" in stages:
        t0 = time.perf_counter()
        nets["stepper"], log = train_stepper(data, Z, recipe.stepper, recipe.stepper_window, recipe.seed, recipe.hidden,
                                             recipe.log_every, csv_path, quiet, stream,
                                             stepper=nets.get("stepper") if resume else None,
                                             log_name="stepper_resumed" if resume else "stepper", par=par)
        wall["stepper" + ("_resumed" if resume else "")] = round(time.perf_counter() - t0, 1)
        summary["first_loss"]["stepper"], summary["final_loss"]["stepper"] = log.first_loss, log.last_loss
        save_all("after stepper")
    if "projector" in stages:
        t0 = time.perf_counter()
        nets["projector"], log = train_projector(data, Z, recipe.projector, recipe.seed, recipe.hidden,
                                                 recipe.log_every, csv_path, quiet, stream,
                                                 projector=nets.get("projector") if resume else None,
                                                 log_name="projector_resumed" if resume else "projector",
                                                 noise=recipe.projector_noise, neighbours=recipe.projector_neighbours,
                                                 margin=recipe.projector_margin, par=par)
        wall["projector" + ("_resumed" if resume else "")] = round(time.perf_counter() - t0, 1)
        summary["first_loss"]["projector"], summary["final_loss"]["projector"] = log.first_loss, log.last_loss
    wall["total_this_run"] = round(time.perf_counter() - t_all, 1)
    save_all("complete" if all(n in nets for n in NETWORKS) else "partial")
    par.barrier()  # every rank returns once rank 0 has written the files
    summary["wall_s"] = wall
    summary["paths"] = {"runtime": str(runtime_path), "compressor": str(comp_path), "log": str(csv_path)}
    return summary

"""Stage 2 of learned motion matching training (Holden et al. 2020, Algorithm 2): the stepper predicts the
time derivative of ``[features, latent]``; trained by autoregressive rollout over a window of frames.
"""
from __future__ import annotations

import numpy as np
import torch

from lmm.offline.distributed import Parallel
from lmm.offline.networks import NormalizedMLP, default_specs
from lmm.offline.training_data import TrainingData, robust_std, window_starts_from
from lmm.offline.training_loop import LossLog, StageSettings, make_optimizer, optimise_step, seed_all

# loss weights from the reference (see shared notes); names are the CSV columns
STEPPER_WEIGHTS = {"features": 2.0, "latent": 7.5, "features_vel": 0.2, "latent_vel": 0.5}


def make_stepper(data: TrainingData, Z: torch.Tensor, windows: np.ndarray, latent: int = 32, hidden: int = 512):
    S = torch.cat([data.X, Z], dim=1).numpy()
    spec = default_specs(n_features=data.X.shape[1], n_latent=Z.shape[1], hidden=hidden)["stepper"]
    stepper = NormalizedMLP(spec)
    d = (S[windows + 1] - S[windows]) / data.dt
    stepper.set_normalization(in_mean=S.mean(0), in_std=robust_std(S), out_mean=d.mean(0), out_std=robust_std(d))
    return stepper


def train_stepper(data: TrainingData, Z: torch.Tensor, s: StageSettings, window: int = 20, seed: int = 1234,
                  hidden: int = 512, log_every: int = 200, csv_path=None, quiet=False, stream=None, verbose=False,
                  stepper=None, log_name: str = "stepper", par: Parallel | None = None):
    par = par or Parallel(torch.device("cpu"))
    rng = seed_all(par.seed(seed + 1))
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
                  quiet or not par.is_main, verbose)
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
        optimise_step(loss, terms, opt, sched, log, it)
    log.close()
    return stepper, log

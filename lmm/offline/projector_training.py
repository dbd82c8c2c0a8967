"""Stage 3 of learned motion matching training (Holden et al. 2020, Algorithm 3): the projector maps a
(noisy) query to the ``[features, latent]`` of its exact nearest frame; the exact nearest neighbours and
the cell term its losses need.
"""
from __future__ import annotations

import numpy as np
import torch

from lmm.offline.distributed import Parallel
from lmm.offline.networks import NormalizedMLP, default_specs
from lmm.offline.training_data import TrainingData, robust_std
from lmm.offline.training_loop import (LossLog, StageSettings, console_progress, make_optimizer, optimise_step,
                                      seed_all)

# The projector's weights differ from the reference's (features 1.0, latent 5.0, distance 0.3): a larger
# features weight and the "cell" term (see train_projector for the measurements behind them).
PROJECTOR_WEIGHTS = {"features": 10.0, "latent": 5.0, "distance": 0.3, "cell": 100.0}


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


def frame_neighbours(X: torch.Tensor, k: int, chunk: int = 2048, aug: torch.Tensor | None = None,
                     progress=None) -> torch.Tensor:
    """The ``k`` nearest other frames of every frame (N x k indices, nearest first). ``chunk`` rows at a
    time, fewer on a CPU where the block would pass :data:`CPU_DISTANCE_BLOCK_BYTES`; ``progress(rows)``
    is called with the rows done after each block (the shipped set's 57,500 frames took 72 s on one thread
    of a shared 2-core machine)."""
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
        if progress is not None:
            progress(min(a + chunk, n))
    return torch.cat(out)


def cpu_index(X: torch.Tensor):
    """The run-time search's index over ``X`` when the projector trains on a CPU and its compiled filter
    is here (see :func:`targets`), else None."""
    if X.device.type != "cpu":
        return None
    from lmm import search_native
    if search_native.library() is None:
        return None
    from lmm.search_index import SearchIndex
    return SearchIndex(X.numpy())


def targets(queries: torch.Tensor, X: torch.Tensor, aug: torch.Tensor, index=None):
    """The exact nearest frames of ``queries`` and their squared distances, as :func:`nearest_neighbours`.
    On a CPU with the compiled search filter (``index``, from :func:`cpu_index`) each query walks the run-time
    search's bounding boxes instead of costing every frame: 17-21 ms against 43-53 ms for 512 queries over
    51,734 frames on one thread (the same frames but for float rounding on near ties, 1 query in 512)."""
    found = index.nearest_frames(queries.numpy()) if index is not None else None
    if found is None:
        return nearest_neighbours(queries, X, aug=aug)
    nn_i = torch.from_numpy(found[0])
    return nn_i, ((queries - X[nn_i]) ** 2).sum(1)


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
                    log_every: int = 200, csv_path=None, quiet=False, stream=None, verbose=False, projector=None,
                    log_name: str = "projector", noise: float = 0.5, neighbours: int = 16, margin: float = 0.1,
                    weights: dict | None = None, skip: bool = True, par: Parallel | None = None):
    """Noisy queries, their exact nearest frames as targets (features and latent), L1 losses, the
    reference's distance term, and the cell term (:func:`cell_violation` against the target's
    ``neighbours`` nearest frames). The projector has a skip connection (features = query + correction).
    ``weights`` overrides :data:`PROJECTOR_WEIGHTS`; ``bench/projector_ablation.py`` varies it and ``skip``
    and measured the choice (table in ``lmm/data/weights/README.md``): the cell term trades feature
    accuracy for landing in the right cell, and too much of it collapses the projector to the identity."""
    par = par or Parallel(torch.device("cpu"))
    rng = seed_all(par.seed(seed + 2))
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
    rivals = None
    if weights["cell"] > 0 and neighbours > 0:   # the stage's longest phase before its loop: its own line
        table = console_progress(X.shape[0], f"{log_name} neighbours", stream, enabled=not quiet and par.is_main)
        rivals = frame_neighbours(X, neighbours, aug=aug, progress=lambda rows: table.update(rows - table.count))
        table.close()
    z_std = torch.from_numpy(robust_std(Z.numpy())).to(par.device)
    pool = data.frames if data.frames is not None else np.arange(X.shape[0])
    index = cpu_index(X)
    opt, sched = make_optimizer(projector.parameters(), s)
    log = LossLog(log_name, s.iterations, log_every, csv_path if par.is_main else None, stream,
                  quiet or not par.is_main, verbose)
    for it in range(s.iterations):
        f = torch.from_numpy(pool[rng.integers(0, len(pool), s.batch)]).to(par.device)
        q = noisy_queries(X, f, x_std, gen, noise)
        nn_i, nn_cost = targets(q, X, aug, index)
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
        optimise_step(loss, terms, opt, sched, log, it)
    log.close()
    return projector, log

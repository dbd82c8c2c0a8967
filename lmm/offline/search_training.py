"""Training of the motion search networks (torch, CPU, minutes): the contrastive window encoder and the
classifier baseline (:mod:`lmm.motion_search.encoder` runs both in numpy).

Both are :class:`TorchConvNet` (1D convolutions over the window's time axis, mean+max pooling, fully
connected layers) trained on windows cut from the frames *before* each take's held-out part
(:mod:`lmm.offline.search_data`), so evaluation queries are never seen in training.

* **Encoder** (64-D, L2-normalised): NT-Xent (InfoNCE over the 2B views of a batch, temperature
  ``temperature``) between two augmented views of the same moment of a take. Each view is cut around
  the same centre (jittered by up to ``jitter`` frames) and played at its own speed in
  ``warp`` (time warp 0.7-1.4x, :func:`lmm.offline.search_data.warped_segments`), mirrored with
  probability ``mirror_p``, its limb positions scaled per limb by up to ``bone_scale`` (other
  proportions), turned by a small yaw error up to ``yaw_deg`` and given Gaussian noise of ``noise`` times
  each feature's spread.
* **Classifier** (the approach this project grew from): the same convolutional trunk, a 512-unit inner
  layer and one output per action label, trained with class-balanced cross-entropy on one view with the
  same augmentations; its embedding is the inner 512-D layer.
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np
import torch
from torch import nn

from lmm.motion_search import encoder as enc
from lmm.motion_search import windows as W
from lmm.offline import search_data as data


@dataclass
class SearchRecipe:
    steps: int = 1000
    batch: int = 256
    lr: float = 2e-3
    weight_decay: float = 1e-4
    temperature: float = 0.1
    warp: tuple[float, float] = (0.7, 1.4)
    jitter: float = 3.0            # frames
    mirror_p: float = 0.5
    bone_scale: float = 0.1        # limb positions scaled by U(1 - b, 1 + b), per limb
    yaw_deg: float = 10.0
    noise: float = 0.05            # x each feature's standard deviation
    temporal: float = 45.0         # frames: a third view centred up to this far away is a positive too
    augment: bool = True           # False: plain windows (speed 1, no mirror, scale, yaw or noise)
    supervised: float = 0.5        # weight of a supervised contrastive term (same action label = positive)
    convs: list = field(default_factory=lambda: [[64, 5, 2], [64, 5, 2], [128, 3, 1]])
    encoder_fcs: list = field(default_factory=lambda: [128, 64])
    classifier_hidden: int = 512
    seed: int = 1
    threads: int = 0               # torch threads; 0: training_loop.auto_threads() (see train --threads)


class TorchConvNet(nn.Module):
    """The torch twin of :class:`lmm.motion_search.encoder.ConvNet` (same layers, same export)."""

    def __init__(self, kind: str, convs, fcs, embed_fc: int, l2_normalize: bool, in_mean, in_std,
                 labels=(), name: str | None = None):
        super().__init__()
        self.kind, self.name = kind, name or kind
        self.conv_spec = [list(map(int, c)) for c in convs]
        self.fc_spec = [int(v) for v in fcs]
        self.embed_fc, self.l2_normalize, self.labels = int(embed_fc), bool(l2_normalize), list(labels)
        self.register_buffer("in_mean", torch.as_tensor(np.asarray(in_mean, np.float32)))
        self.register_buffer("in_std", torch.as_tensor(np.asarray(in_std, np.float32)))
        c = W.FRAME_DIM
        self.convs = nn.ModuleList()
        for out, k, stride in self.conv_spec:
            self.convs.append(nn.Conv1d(c, out, k, stride=stride, padding=k // 2))
            c = out
        self.fcs = nn.ModuleList()
        f = 2 * c
        for out in self.fc_spec:
            self.fcs.append(nn.Linear(f, out))
            f = out

    def trunk(self, x: torch.Tensor) -> torch.Tensor:
        x = ((x - self.in_mean) / self.in_std).transpose(1, 2)   # (n, C, T)
        for conv in self.convs:
            x = torch.relu(conv(x))
        return torch.cat([x.mean(dim=2), x.amax(dim=2)], dim=1)

    def head(self, h: torch.Tensor, n_layers: int) -> torch.Tensor:
        for i in range(n_layers):
            h = self.fcs[i](h)
            if i < len(self.fcs) - 1:
                h = torch.relu(h)
        return h

    def embed(self, x: torch.Tensor) -> torch.Tensor:
        h = self.head(self.trunk(x), self.embed_fc)
        return nn.functional.normalize(h, dim=1) if self.l2_normalize else h

    def logits(self, x: torch.Tensor) -> torch.Tensor:
        return self.head(self.trunk(x), len(self.fcs))

    def metadata(self) -> dict:
        return {"kind": self.kind, "name": self.name, "convs": self.conv_spec, "fcs": self.fc_spec,
                "embed_fc": self.embed_fc, "l2_normalize": self.l2_normalize, "labels": self.labels}

    def to_arrays(self) -> dict[str, np.ndarray]:
        out = {"in_mean": self.in_mean.numpy().copy(), "in_std": self.in_std.numpy().copy()}
        for i, conv in enumerate(self.convs):
            out[f"conv{i}.weight"] = conv.weight.detach().numpy().copy()
            out[f"conv{i}.bias"] = conv.bias.detach().numpy().copy()
        for i, fc in enumerate(self.fcs):
            out[f"fc{i}.weight"] = fc.weight.detach().numpy().copy()
            out[f"fc{i}.bias"] = fc.bias.detach().numpy().copy()
        return out

    def save(self, path, training: dict | None = None) -> Path:
        return enc.save(path, self.to_arrays(), dict(self.metadata(), training=training or {}))


class ViewSampler:
    """Augmented windows cut from a list of frame arrays (see the module doc)."""

    def __init__(self, frames: list[np.ndarray], recipe: SearchRecipe, scale: np.ndarray, rng):
        self.r, self.rng, self.scale = recipe, rng, scale.astype(np.float32)
        # room for the longest view around a centre, plus the jitter
        self.half = 0.5 * (W.WINDOW_FRAMES - 1) * recipe.warp[1] + recipe.jitter + recipe.temporal + 1
        self.takes = [i for i, f in enumerate(frames) if len(f) > 2 * self.half + 1]
        if not self.takes:
            raise data.SearchDataError("no take is long enough to cut training windows from")
        self.frames = frames
        room = np.array([len(frames[i]) - 2 * self.half for i in self.takes], np.float64)
        self.p = room / room.sum()

    def centres(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        which = self.rng.choice(len(self.takes), size=n, p=self.p)
        takes = np.array(self.takes)[which]
        lo = self.half
        hi = np.array([len(self.frames[t]) - 1 - self.half for t in takes])
        return takes, lo + self.rng.random(n) * (hi - lo)

    def views(self, takes: np.ndarray, centres: np.ndarray) -> np.ndarray:
        r, rng, n = self.r, self.rng, len(takes)
        if not r.augment:
            speeds, c = np.ones(n), np.round(centres)
        else:
            speeds = np.exp(rng.uniform(math.log(r.warp[0]), math.log(r.warp[1]), n))
            c = centres + rng.uniform(-r.jitter, r.jitter, n)
        starts = c - 0.5 * (W.WINDOW_FRAMES - 1) * speeds
        out = np.empty((n, W.WINDOW_FRAMES, W.FRAME_DIM), np.float32)
        for t in np.unique(takes):
            sel = takes == t
            out[sel] = data.warped_segments(self.frames[t], starts[sel], speeds[sel])
        return self.augment(out) if r.augment else out

    def augment(self, x: np.ndarray) -> np.ndarray:
        r, rng, n = self.r, self.rng, len(x)
        flip = rng.random(n) < r.mirror_p
        x[flip] = W.mirror_frames(x[flip])
        n_limbs = len(W.LIMB_JOINTS)
        limbs = x[..., : 3 * n_limbs].reshape(n, W.WINDOW_FRAMES, n_limbs, 3)
        limbs *= rng.uniform(1 - r.bone_scale, 1 + r.bone_scale, (n, 1, n_limbs, 1)).astype(np.float32)
        a = np.deg2rad(rng.uniform(-r.yaw_deg, r.yaw_deg, n)).astype(np.float32)
        cos, sin = np.cos(a)[:, None, None], np.sin(a)[:, None, None]
        lx, lz = limbs[..., 0].copy(), limbs[..., 2].copy()
        limbs[..., 0], limbs[..., 2] = cos * lx - sin * lz, sin * lx + cos * lz
        x[..., : 3 * n_limbs] = limbs.reshape(n, W.WINDOW_FRAMES, -1)
        vx, vz = x[..., -3].copy(), x[..., -2].copy()
        x[..., -3], x[..., -2] = cos[..., 0] * vx - sin[..., 0] * vz, sin[..., 0] * vx + cos[..., 0] * vz
        x += rng.normal(0.0, r.noise, x.shape).astype(np.float32) * self.scale
        return x


def nt_xent(z1: torch.Tensor, z2: torch.Tensor, temperature: float) -> torch.Tensor:
    """NT-Xent over 2B L2-normalised views: each view's positive is its twin, the other 2B - 2 the
    negatives."""
    z = torch.cat([z1, z2])
    sim = z @ z.T / temperature
    sim.fill_diagonal_(float("-inf"))
    b = len(z1)
    target = torch.cat([torch.arange(b, 2 * b), torch.arange(0, b)])
    return nn.functional.cross_entropy(sim, target)


def sup_con(z: torch.Tensor, labels: torch.Tensor, temperature: float) -> torch.Tensor:
    """Supervised contrastive loss (Khosla et al. 2020): every other view with the same label is a
    positive; the mean over each anchor's positives of -log softmax."""
    sim = z @ z.T / temperature
    eye = torch.eye(len(z), dtype=torch.bool)
    sim = sim.masked_fill(eye, float("-inf"))
    logp = sim - torch.logsumexp(sim, dim=1, keepdim=True)
    pos = (labels[:, None] == labels[None, :]) & ~eye
    n_pos = pos.sum(dim=1)
    per_anchor = -(logp.masked_fill(~pos, 0.0)).sum(dim=1) / n_pos.clamp(min=1)
    return per_anchor[n_pos > 0].mean()


def _schedule(opt, step: int, steps: int, lr: float) -> None:
    warm = max(1, steps // 50)
    f = step / warm if step < warm else 0.5 * (1 + math.cos(math.pi * (step - warm) / max(1, steps - warm)))
    for g in opt.param_groups:
        g["lr"] = lr * max(f, 0.01)


def normalisation(frames: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    allf = np.concatenate(frames).astype(np.float64)
    return allf.mean(axis=0).astype(np.float32), np.maximum(allf.std(axis=0), 1e-3).astype(np.float32)


def train(takes: list[data.Take], kind: str, recipe: SearchRecipe | None = None, log=print) -> tuple[TorchConvNet, dict]:
    """Train the ``encoder`` or the ``classifier`` on the training part of ``takes``; the network and a
    record of the run (recipe, split, loss curve, wall time)."""
    r = recipe or SearchRecipe()
    if not r.threads:
        from dataclasses import replace

        from lmm.offline.training_loop import auto_threads
        r = replace(r, threads=auto_threads())
    torch.set_num_threads(r.threads)
    torch.manual_seed(r.seed)
    rng = np.random.default_rng(r.seed)
    frames = data.training_frames(takes)
    mean, std = normalisation(frames)
    sampler = ViewSampler(frames, r, std, rng)
    labels = data.labels_of(takes)
    take_label = np.array([labels.index(t.label) for t in takes])
    if kind == "encoder":
        net = TorchConvNet("encoder", r.convs, r.encoder_fcs, len(r.encoder_fcs), True, mean, std)
    elif kind == "classifier":
        net = TorchConvNet("classifier", r.convs, [r.classifier_hidden, len(labels)], 1, False, mean, std, labels)
        counts = np.bincount(take_label, weights=[len(f) for f in frames], minlength=len(labels))
        class_w = torch.as_tensor(counts.sum() / np.maximum(counts, 1) / len(labels), dtype=torch.float32)
    else:
        raise ValueError(f"unknown kind {kind!r}")
    opt = torch.optim.AdamW(net.parameters(), lr=r.lr, weight_decay=r.weight_decay)
    losses, t0 = [], time.perf_counter()
    for step in range(r.steps):
        _schedule(opt, step, r.steps, r.lr)
        tk, c = sampler.centres(r.batch)
        if kind == "encoder":
            z1 = net.embed(torch.from_numpy(sampler.views(tk, c)))
            z2 = net.embed(torch.from_numpy(sampler.views(tk, c)))
            loss = nt_xent(z1, z2, r.temperature)
            zs = [z1, z2]
            if r.temporal > 0:
                z3 = net.embed(torch.from_numpy(sampler.views(tk, c + rng.uniform(-r.temporal, r.temporal, len(c)))))
                loss = loss + nt_xent(z1, z3, r.temperature)
                zs.append(z3)
            if r.supervised > 0:
                lab = torch.as_tensor(np.tile(take_label[tk], len(zs)))
                loss = loss + r.supervised * sup_con(torch.cat(zs), lab, r.temperature)
        else:
            v = torch.from_numpy(sampler.views(tk, c))
            loss = nn.functional.cross_entropy(net.logits(v), torch.as_tensor(take_label[tk]), weight=class_w)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(float(loss.detach()))
        if log and (step % 100 == 0 or step == r.steps - 1):
            log(f"{kind} step {step:5d}/{r.steps} loss {np.mean(losses[-100:]):.4f} "
                f"({time.perf_counter() - t0:.0f} s)")
    record = {"recipe": asdict(r), "held_out_fraction": data.HELD_OUT_FRACTION,
              "takes": [t.file for t in takes], "labels": labels,
              "training_windows": int(sum(max(0, len(f) - W.WINDOW_FRAMES + 1) for f in frames)),
              "loss_every_100": [round(float(np.mean(losses[i:i + 100])), 5) for i in range(0, len(losses), 100)],
              "wall_s": round(time.perf_counter() - t0, 1), "torch_threads": r.threads}
    return net.eval(), record


def main(argv=None) -> int:
    import argparse

    p = argparse.ArgumentParser(prog="python -m lmm.offline.search_training",
                                description="train the motion search encoder and the classifier baseline")
    p.add_argument("--data", help=f"folder of BVH takes (default: {data.DEFAULT_DATA_DIR})")
    p.add_argument("--out", default=str(enc.DEFAULT_WEIGHTS.parent), help="folder for the .npz files")
    p.add_argument("--steps", type=int, default=SearchRecipe.steps)
    p.add_argument("--threads", type=int, default=SearchRecipe.threads, help="torch threads (default 0: auto)")
    p.add_argument("--only", choices=["encoder", "classifier"])
    p.add_argument("--temporal", type=float, default=SearchRecipe.temporal)
    p.add_argument("--supervised", type=float, default=SearchRecipe.supervised)
    p.add_argument("--no-augment", dest="augment", action="store_false", help="train on plain windows")
    args = p.parse_args(argv)
    takes = data.load_takes(args.data)
    recipe = SearchRecipe(steps=args.steps, threads=args.threads, temporal=args.temporal,
                          supervised=args.supervised, augment=args.augment)
    out = Path(args.out)
    for kind in (args.only,) if args.only else ("encoder", "classifier"):
        net, record = train(takes, kind, recipe)
        target = enc.DEFAULT_WEIGHTS.name if kind == "encoder" else enc.CLASSIFIER_WEIGHTS.name
        net.save(out / target, record)
        print(f"{kind}: {out / target} ({record['wall_s']} s)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Stage 1 of learned motion matching training (Holden et al. 2020, Algorithm 1): the compressor (training
only) and the decompressor, trained jointly as an auto-encoder whose bottleneck is ``[matching features,
latent]``; losses in local and character space (forward kinematics), their frame-to-frame changes, and
latent regularisation.
"""
from __future__ import annotations

import torch
import torch.nn.functional as F

from lmm.kinematics import forward_kinematics_velocity_joints
from lmm.nn import pose_vector_size, pose_vector_slices
from lmm.offline.distributed import Parallel
from lmm.offline.networks import NormalizedMLP, default_specs
from lmm.offline.training_data import TrainingData, robust_std
from lmm.offline.training_loop import LossLog, StageSettings, make_optimizer, optimise_step, seed_all

# loss weights from the reference (see shared notes); names are the CSV columns
DECOMPRESSOR_WEIGHTS = {
    "loc_pos": 75.0, "loc_rot": 10.0, "loc_vel": 10.0, "loc_angvel": 1.25, "root_vel": 2.0, "root_angvel": 2.0,
    "contacts": 2.0, "chr_pos": 15.0, "chr_rot": 5.0, "chr_vel": 2.0, "chr_angvel": 0.75,
    "pos_change": 10.0, "rot_change": 1.75, "chr_pos_change": 2.0, "chr_rot_change": 0.75,
    "latent_l1": 0.1, "latent_l2": 0.1, "latent_vel": 0.01,
}


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
    """Forward kinematics with velocities on rotation matrices (the recursion of
    :func:`lmm.kinematics.forward_kinematics_velocity_joints`). Shapes (B, J, 3, 3) / (B, J, 3)."""
    def rotate(m, v):
        return (m @ v[..., None])[..., 0]

    out = forward_kinematics_velocity_joints(rot.unbind(1), pos.unbind(1), vel.unbind(1), ang.unbind(1), parents,
                                             torch.matmul, rotate, torch.linalg.cross)
    return tuple(torch.stack(x, 1) for x in out)


# ---------------------------------------------------------------------------------------------
# the networks, their losses and the loop
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


def train_decompressor(data: TrainingData, s: StageSettings, seed: int = 1234, latent: int = 32, hidden: int = 512,
                       log_every: int = 200, csv_path=None, quiet: bool = False, stream=None, verbose: bool = False,
                       networks=None, checkpoint=None, par: Parallel | None = None):
    """Train compressor + decompressor jointly. Returns (compressor, decompressor, LossLog).
    ``par``: the device and the processes taking part (default: this process on the CPU)."""
    par = par or Parallel(torch.device("cpu"))
    rng = seed_all(par.seed(seed))
    compressor, decompressor = networks or make_autoencoder(data, latent, hidden)
    run_c, run_d = par.wrap(compressor), par.wrap(decompressor)
    data = data.to(par.device)
    c_in = data.compressor_input
    params = list(compressor.parameters()) + list(decompressor.parameters())
    opt, sched = make_optimizer(params, s)
    log = LossLog("decompressor", s.iterations, log_every, csv_path if par.is_main else None, stream,
                  quiet or not par.is_main, verbose)
    starts = data.windows2
    for it in range(s.iterations):
        f0 = torch.from_numpy(starts[rng.integers(0, len(starts), s.batch)]).to(par.device)
        frames = torch.cat([f0, f0 + 1])
        z = run_c(c_in[frames])
        y_hat = run_d(torch.cat([data.X[frames], z], dim=1))
        terms = decompressor_losses(y_hat, data.Y[frames], data.Q[frames], z, data, s.batch)
        loss = sum(DECOMPRESSOR_WEIGHTS[k] * v for k, v in terms.items())
        optimise_step(loss, terms, opt, sched, log, it)
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

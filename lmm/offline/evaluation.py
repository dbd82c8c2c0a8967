"""Quality metrics of the learned motion matching networks, numpy only (``lmm-studio eval``).

=====================================  ==================================================================
key                                    meaning
=====================================  ==================================================================
decompressor.mean_joint_error_cm       mean character-space joint position error over every database frame
                                       (latent from the compressor, features from the database)
projector.nn_agreement                 over noisy queries built as in training, the fraction where the frame
                                       nearest to the projector's features is the query's true nearest
projector.cost_ratio_median            query cost of the projected features / query cost of the true NN
                                       (below 1: the projection lies between the query and its nearest frame)
projector.*_runtime                    the same on the queries MM makes on the MM vs LMM run's input
projector.{query,projection}_to_nn_median  median distance of the query / of the projection to the true NN
projector.latent_error_mean_abs_std    projected latent vs the true NN's (compressor) latent, in latent stds
stepper.drift_60                       mean absolute normalised feature error after a 60-frame rollout
mm_vs_lmm.mean_joint_distance_cm       MM and LMM fed the same built-in input: mean distance of the joints
                                       in each character's root space
foot_skating.{mm,lmm}_cm_s             mean horizontal toe speed while the toe is in contact and grounded
=====================================  ==================================================================
"""
from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np

from lmm import quat
from lmm.nn import MLP, character_parents, character_space, decode_pose_vector, pose_vectors
from lmm.data.weights import load as load_weights


def load_compressor(path, db=None, features=None) -> MLP:
    wf = load_weights(path, require=["compressor"], db_key=None if db is None else db.key,
                      layout_dicts=None if features is None else features.layout_dicts())
    return MLP.from_spec(wf.arrays, "compressor", wf.spec("compressor"))


def batched(fn, x: np.ndarray, chunk: int = 4096) -> np.ndarray:
    return np.concatenate([fn(x[i:i + chunk]) for i in range(0, x.shape[0], chunk)])


def database_latents(compressor: MLP, db) -> np.ndarray:
    """The compressor's latent of every database frame, (N, L) float32."""
    c_in = np.concatenate([pose_vectors(db), character_space(db)], axis=1)
    return batched(compressor, c_in)


def character_positions(y: np.ndarray, n_bones: int, parents) -> np.ndarray:
    """Character-space joint positions (n, J-1, 3) from pose vectors."""
    p = decode_pose_vector(y.astype(np.float64), n_bones)
    _, g_pos = quat.forward_kinematics(p["rotations"], p["positions"], character_parents(parents))
    return g_pos


def decompressor_error(nets, db, features, Z: np.ndarray) -> dict:
    X = nets.to_network_space(features.raw)
    y_hat = batched(nets.decompressor, np.concatenate([X, Z], axis=1).astype(np.float32))
    ref = character_space(db)[:, :3 * (db.n_bones - 1)].reshape(db.n_frames, db.n_bones - 1, 3)
    got = character_positions(y_hat, db.n_bones, db.parents)
    err = np.linalg.norm(got - ref, axis=-1) * 100.0  # cm, (N, J-1)
    return {"mean_joint_error_cm": float(err.mean()), "std_joint_error_cm": float(err.std()),
            "max_joint_error_cm": float(err.max()),
            "per_joint_cm": {name: float(v) for name, v in zip(db.names[1:], err.mean(0))}}


def noisy_queries(X: np.ndarray, n: int, rng: np.random.Generator, noise: float = 0.5) -> tuple[np.ndarray, np.ndarray]:
    """As in training: x + noise * std * U(0, 1) * N(0, 1), x a random database frame's features."""
    frames = rng.integers(0, X.shape[0], n)
    level = rng.random((n, 1)) * noise
    q = X[frames] + X.std(0) * level * rng.standard_normal((n, X.shape[1]))
    return q.astype(np.float32), frames


def nearest(queries: np.ndarray, X: np.ndarray, chunk: int = 512) -> tuple[np.ndarray, np.ndarray]:
    """Exact nearest neighbours (squared Euclidean): indices and costs."""
    x_sq = np.einsum("ij,ij->i", X, X)
    idx = np.empty(queries.shape[0], np.int64)
    for a in range(0, queries.shape[0], chunk):
        q = queries[a:a + chunk]
        d = x_sq[None, :] - 2.0 * q @ X.T
        idx[a:a + chunk] = np.argmin(d, axis=1)
    cost = np.sum((queries - X[idx]) ** 2, axis=1)
    return idx, cost


def training_noise(nets) -> float:
    """The projector's query noise level from the weights' recipe (1.0 for files from before it was stored)."""
    return float(nets.metadata.get("recipe", {}).get("projector_noise", 1.0))


def projection_stats(nets, X: np.ndarray, q: np.ndarray, Z: np.ndarray | None = None) -> dict:
    """The projector on queries ``q`` (network space) against their exact nearest frames in ``X``:
    agreement, cost ratio, feature error and the distances of query and projection to the true frame;
    with the database latents ``Z`` (from the compressor) also the projected latent's error, in latent stds."""
    nn_idx, nn_cost = nearest(q, X)
    full = batched(nets.projector, q)
    proj = full[:, :nets.n_features]
    proj_nn, _ = nearest(proj, X)
    ratio = np.sum((q - proj) ** 2, axis=1) / np.maximum(nn_cost, 1e-9)
    out = {"nn_agreement": float(np.mean(proj_nn == nn_idx)), "cost_ratio_median": float(np.median(ratio)),
           "nn_within_3_frames": float(np.mean(np.abs(proj_nn - nn_idx) <= 3)), "cost_ratio_mean": float(np.mean(ratio)),
           "feature_error_mean_abs": float(np.mean(np.abs(proj - X[nn_idx]))),
           "query_to_nn_median": _median_norm(q - X[nn_idx]), "projection_to_nn_median": _median_norm(proj - X[nn_idx])}
    if Z is not None:
        err = np.abs(full[:, nets.n_features:] - Z[nn_idx]) / np.maximum(Z.std(0), 1e-6)
        out["latent_error_mean_abs_std"] = float(err.mean())
    return out


def _median_norm(v: np.ndarray) -> float:
    return float(np.median(np.linalg.norm(v, axis=1)))


def projector_metrics(nets, features, n_queries: int = 4096, seed: int = 7, noise: float | None = None,
                      Z: np.ndarray | None = None) -> dict:
    """:func:`projection_stats` on ``n_queries`` noisy queries built as in training."""
    X = nets.to_network_space(features.raw)
    noise = training_noise(nets) if noise is None else noise
    q, _ = noisy_queries(X, n_queries, np.random.default_rng(seed), noise)
    return projection_stats(nets, X, q, Z) | {"query_noise": noise, "n_queries": int(n_queries)}


RUNTIME_KEYS = ("nn_agreement", "cost_ratio_median", "feature_error_mean_abs", "query_to_nn_median",
                "projection_to_nn_median")


def projector_runtime_agreement(nets, features, queries_norm: np.ndarray) -> dict:
    """:func:`projection_stats` on real queries (those a controller made at its searches), keys + ``_runtime``."""
    if queries_norm.shape[0] == 0:
        return {}
    X = nets.to_network_space(features.raw)
    q = nets.to_network_space(features.denormalize(queries_norm))
    stats = projection_stats(nets, X, q)
    return {f"{k}_runtime": stats[k] for k in RUNTIME_KEYS} | {"runtime_queries": int(q.shape[0])}


def stepper_drift(nets, db, features, Z: np.ndarray, horizon: int = 60, n_starts: int = 2048, seed: int = 11) -> dict:
    """Roll the stepper ``horizon`` frames from database frames; compare with the database there."""
    rng = np.random.default_rng(seed)
    starts = []
    for a, b in zip(db.range_starts, db.range_stops):
        if b - a > horizon:
            starts.append(np.arange(a, b - horizon))
    starts = np.concatenate(starts)
    starts = starts[rng.integers(0, len(starts), min(n_starts, len(starts)))]
    X = nets.to_network_space(features.raw)
    S = np.concatenate([X, Z], axis=1).astype(np.float32)
    s = S[starts].copy()
    dt = np.float32(db.dt)
    for _ in range(horizon):
        s += dt * nets.stepper(s)
    d = nets.n_features
    target = S[starts + horizon]
    return {f"drift_{horizon}": float(np.mean(np.abs(s[:, :d] - target[:, :d]))),
            f"latent_drift_{horizon}": float(np.mean(np.abs(s[:, d:] - target[:, d:]) / (Z.std(0) + 1e-6))),
            "finite": bool(np.all(np.isfinite(s)))}


# ---------------------------------------------------------------------------------------------
# the two controllers side by side
# ---------------------------------------------------------------------------------------------

def run_controller(controller, inputs, seconds: float, dt: float = 1.0 / 60.0) -> dict:
    """Step a controller through an input log; world joint positions, root transforms, contacts, latents."""
    n = int(round(seconds / dt))
    J = controller.db.n_bones
    pos = np.zeros((n, J, 3), np.float32)
    root_pos = np.zeros((n, 3))
    root_rot = np.zeros((n, 4))
    contacts = np.zeros((n, 2), bool)
    latents, queries = [], []
    step_us = np.zeros(n)
    for i in range(n):
        t0 = time.perf_counter()
        pose, snap = controller.step(inputs.at(i * dt), dt)
        step_us[i] = (time.perf_counter() - t0) * 1e6
        pos[i] = pose.global_positions
        root_pos[i] = pose.global_positions[0]
        root_rot[i] = pose.global_rotations[0]
        contacts[i] = pose.contacts
        if snap.latent is not None:
            latents.append(snap.latent)
        if snap.searched:
            queries.append(snap.query)
    return {"positions": pos, "root_position": root_pos, "root_rotation": root_rot, "contacts": contacts,
            "latents": np.array(latents) if latents else None, "step_us": step_us, "dt": dt,
            "queries": np.array(queries, np.float32).reshape(-1, controller.features.n_dims)}


def root_space(run: dict) -> np.ndarray:
    rel = run["positions"].astype(np.float64) - run["root_position"][:, None]
    return quat.inv_mul_vec(run["root_rotation"][:, None], rel)


def foot_skating_cm_s(run: dict, toe_bones, height_m: float = 0.05) -> float:
    """Mean horizontal toe speed (cm/s) over frames where the toe is marked in contact and near the ground."""
    pos = run["positions"][:, toe_bones].astype(np.float64)  # (n, 2, 3)
    vel = np.linalg.norm(np.diff(pos[..., [0, 2]], axis=0), axis=-1) / run["dt"]
    grounded = run["contacts"][1:] & (pos[1:, :, 1] < height_m)
    return float(vel[grounded].mean() * 100.0) if grounded.any() else 0.0


def bone_length_error_m(run: dict, db) -> float:
    """Largest deviation of any bone length from the database skeleton's (m)."""
    ref = np.linalg.norm(db.positions[0, 1:].astype(np.float64), axis=-1)
    pos = run["positions"].astype(np.float64)
    parents = db.parents
    lengths = np.linalg.norm(pos[:, 2:] - pos[:, parents[2:]], axis=-1)
    return float(np.max(np.abs(lengths - ref[1:]))) if lengths.size else 0.0


def evaluate(db, features, nets, compressor: MLP, inputs="builtin:random:1", seconds: float = 60.0,
             n_queries: int = 4096, log=print) -> tuple[dict, dict]:
    """All metrics. Returns (metrics, artifacts for the plots)."""
    from lmm.data.inputs import open_input
    from lmm.learned import LearnedMotionMatchingController
    from lmm.mm import MotionMatchingController

    out: dict = {"database": {"name": db.name, "key": db.key, "frames": db.n_frames},
                 "weights": str(nets.path) if nets.path else None}
    t0 = time.perf_counter()
    Z = database_latents(compressor, db)
    dec = decompressor_error(nets, db, features, Z)
    per_joint = dec.pop("per_joint_cm")
    out["decompressor"] = dec
    log(f"decompressor: mean joint error {dec['mean_joint_error_cm']:.3f} cm ({time.perf_counter() - t0:.1f} s)")
    t0 = time.perf_counter()
    out["projector"] = projector_metrics(nets, features, n_queries, Z=Z)
    log(f"projector: nn agreement {out['projector']['nn_agreement']:.3f}, cost ratio median "
        f"{out['projector']['cost_ratio_median']:.3f} ({time.perf_counter() - t0:.1f} s)")
    t0 = time.perf_counter()
    out["stepper"] = stepper_drift(nets, db, features, Z)
    log(f"stepper: drift_60 {out['stepper']['drift_60']:.4f} ({time.perf_counter() - t0:.1f} s)")
    t0 = time.perf_counter()
    log_in = open_input(inputs, seconds)
    mm = run_controller(MotionMatchingController(db, features), log_in, seconds)
    lmm = run_controller(LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False),
                         log_in, seconds)
    dist = np.linalg.norm(root_space(mm) - root_space(lmm), axis=-1) * 100.0
    toes = [db.bone("left_toe"), db.bone("right_toe")]
    out["mm_vs_lmm"] = {"mean_joint_distance_cm": float(dist.mean()), "input": inputs, "seconds": seconds,
                        "root_distance_cm": float(np.mean(np.linalg.norm(mm["root_position"] - lmm["root_position"],
                                                                         axis=-1)) * 100.0)}
    out["projector"].update(projector_runtime_agreement(nets, features, mm["queries"]))
    out["foot_skating"] = {"mm_cm_s": foot_skating_cm_s(mm, toes), "lmm_cm_s": foot_skating_cm_s(lmm, toes)}
    out["lmm_run"] = {"finite": bool(np.all(np.isfinite(lmm["positions"]))),
                      "max_bone_length_error_cm": bone_length_error_m(lmm, db) * 100.0,
                      "median_step_us": float(np.median(lmm["step_us"]))}
    log(f"mm vs lmm: mean joint distance {dist.mean():.2f} cm; foot skating mm {out['foot_skating']['mm_cm_s']:.2f} "
        f"lmm {out['foot_skating']['lmm_cm_s']:.2f} cm/s ({time.perf_counter() - t0:.1f} s)")
    artifacts = {"per_joint_cm": per_joint, "latents": lmm["latents"], "dt": lmm["dt"]}
    return out, artifacts


# ---------------------------------------------------------------------------------------------
# plots
# ---------------------------------------------------------------------------------------------

def read_loss_csv(path) -> dict[str, dict[str, np.ndarray]]:
    out: dict[str, dict[str, list]] = {}
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            d = out.setdefault(row["network"], {})
            for k, v in row.items():
                if k != "network" and v not in (None, ""):
                    d.setdefault(k, []).append(float(v))
    return {n: {k: np.array(v) for k, v in d.items()} for n, d in out.items()}


def write_plots(out_dir, artifacts: dict, loss_csv=None) -> list[str]:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    written = []

    def save(fig, name):
        fig.tight_layout()
        fig.savefig(out_dir / name, dpi=110)
        plt.close(fig)
        written.append(str(out_dir / name))

    if loss_csv and Path(loss_csv).exists():
        losses = read_loss_csv(loss_csv)
        fig, axes = plt.subplots(1, max(len(losses), 1), figsize=(5 * max(len(losses), 1), 3.5), squeeze=False)
        for ax, (name, d) in zip(axes[0], losses.items()):
            ax.semilogy(d["iteration"], d["loss"], label="total", color="k")
            for k, v in d.items():
                if k not in ("iteration", "elapsed_s", "lr", "loss"):
                    ax.semilogy(d["iteration"], v, lw=0.8, alpha=0.7, label=k)
            ax.set_title(name)
            ax.set_xlabel("iteration")
            ax.legend(fontsize=5, ncol=2)
        save(fig, "training_losses.png")
    if artifacts.get("latents") is not None:
        lat = artifacts["latents"]
        t = np.arange(lat.shape[0]) * artifacts["dt"]
        fig, ax = plt.subplots(figsize=(9, 3.5))
        for k in range(min(lat.shape[1], 8)):
            ax.plot(t, lat[:, k], lw=0.8, label=f"z{k}")
        ax.set_xlabel("time (s)")
        ax.set_title("LMM latent (first 8 dims)")
        ax.legend(fontsize=6, ncol=4)
        save(fig, "latent_traces.png")
    if artifacts.get("per_joint_cm"):
        names = list(artifacts["per_joint_cm"])
        vals = [artifacts["per_joint_cm"][n] for n in names]
        fig, ax = plt.subplots(figsize=(9, 3.5))
        ax.bar(range(len(names)), vals)
        ax.set_xticks(range(len(names)))
        ax.set_xticklabels(names, rotation=70, fontsize=7)
        ax.set_ylabel("mean error (cm)")
        ax.set_title("decompressor: character-space joint position error")
        save(fig, "per_joint_error.png")
    return written


# ---------------------------------------------------------------------------------------------
# benchmark figures (the paper's Table 3): used by `lmm-studio bench`
# ---------------------------------------------------------------------------------------------

def mm_runtime_bytes(db, features) -> dict:
    """What motion matching keeps in memory at run time: features, pose database, search structure."""
    from lmm.search import SearchIndex
    index = SearchIndex(features.normalized)
    if hasattr(index, "nbytes"):
        search = int(index.nbytes() if callable(index.nbytes) else index.nbytes)
    else:  # every array the index holds, except views of the features themselves
        search = sum(v.nbytes for v in vars(index).values()
                     if isinstance(v, np.ndarray) and not np.shares_memory(v, features.normalized))
    return {"features": int(features.normalized.nbytes), "pose": int(db.pose_bytes()), "search": int(search)}


def benchmark_lmm(db, features, nets=None, inputs="builtin:random:1", steps: int = 600, warmup: int = 60) -> dict:
    """``frame.lmm_us`` (median learned-controller step, debug comparison off), the per-network
    costs, and ``memory.mm_bytes`` / ``memory.lmm_bytes``."""
    from lmm.data.inputs import open_input
    from lmm.learned import LearnedMotionMatchingController, load_default_networks

    nets = nets if nets is not None else load_default_networks(db, features)
    ctrl = LearnedMotionMatchingController(db, features, networks=nets, compare_with_search=False)
    log = open_input(inputs, (steps + warmup) / 60.0 + 1.0)
    dt = 1.0 / 60.0
    step_us, adv_us, proj_us = [], [], []
    for i in range(steps + warmup):
        t0 = time.perf_counter()
        _, snap = ctrl.step(log.at(i * dt), dt)
        if i >= warmup:
            step_us.append((time.perf_counter() - t0) * 1e6)
            adv_us.append(snap.timings_us.get("advance", np.nan))
            if "projector" in snap.timings_us:
                proj_us.append(snap.timings_us["projector"])
    # the networks alone at batch 1, as in the paper's table
    state = np.zeros(nets.n_features + nets.n_latent, np.float32)
    query = np.zeros(nets.n_features, np.float32)

    def median_us(fn, n=300):
        fn()
        ts = []
        for _ in range(n):
            t0 = time.perf_counter()
            fn()
            ts.append((time.perf_counter() - t0) * 1e6)
        return float(np.median(ts))

    mm = mm_runtime_bytes(db, features)
    return {
        "frame.lmm_us": float(np.median(step_us)),
        "frame.lmm_advance_us": float(np.nanmedian(adv_us)),
        "frame.lmm_projector_us": float(np.median(proj_us)) if proj_us else float("nan"),
        "network.decompressor_us": median_us(lambda: nets.decompressor(state)),
        "network.stepper_us": median_us(lambda: nets.stepper(state)),
        "network.projector_us": median_us(lambda: nets.projector(query)),
        "memory.mm_bytes": int(sum(mm.values())),
        "memory.mm_features_bytes": mm["features"], "memory.mm_pose_bytes": mm["pose"],
        "memory.mm_search_bytes": mm["search"],
        "memory.lmm_bytes": int(nets.nbytes()),
        "memory.lmm_over_mm": float(nets.nbytes() / max(sum(mm.values()), 1)),
    }

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
foot_skating.{mm,lmm}_cm_s             mean horizontal toe speed while the toe is in contact, by the rule of
                                       :class:`lmm.metrics.FootSkating` (the same as ``lmm-studio run``)
ground_skating.{mm,lmm,source}         fraction of ground-level toe steps faster than 30 cm/s, by the rule of
                                       :class:`lmm.metrics.GroundSkating` (as ``lmm-studio run``); source: the
                                       database's source ranges
=====================================  ==================================================================
"""
from __future__ import annotations

import csv
import time
from pathlib import Path

import numpy as np

from lmm import kinematics, quat
from lmm.latents import batched, database_latents, load_compressor  # noqa: F401 (app/commands/eval.py imports it from here)
from lmm.nn import MLP, character_parents, character_space, decode_pose_vector


def character_positions(y: np.ndarray, n_bones: int, parents) -> np.ndarray:
    """Character-space joint positions (n, J-1, 3) from pose vectors."""
    p = decode_pose_vector(y.astype(np.float64), n_bones)
    _, g_pos = kinematics.forward_kinematics(p["rotations"], p["positions"], character_parents(parents))
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
    """Exact nearest neighbours (squared Euclidean): indices and costs. The matmul form ranks the frames;
    those within its rounding of the least are costed directly, and equal costs go to the lowest frame, so
    identical frames (an idle range repeats frames of a locomotion range) always give the same answer,
    wherever the matrix product's blocking put them."""
    x_sq = np.einsum("ij,ij->i", X, X)
    idx = np.empty(queries.shape[0], np.int64)
    for a in range(0, queries.shape[0], chunk):
        q = queries[a:a + chunk]
        d = x_sq[None, :] - 2.0 * q @ X.T
        least = d.min(axis=1)
        slack = 1e-5 * (float(x_sq.max()) + np.einsum("ij,ij->i", q, q)) + 1e-12
        for r in range(len(q)):
            near = np.flatnonzero(d[r] <= least[r] + slack[r])
            diff = X[near] - q[r]
            costs = np.einsum("ij,ij->i", diff, diff)
            idx[a + r] = near[int(np.argmin(costs))]   # the first least: the lowest frame
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

def run_controllers(controllers: dict, inputs, seconds: float, dt: float = 1.0 / 60.0) -> dict[str, dict]:
    """Step controllers side by side through an input log (:func:`lmm.runner.step_controllers`, the one
    tick loop); per controller: world joint positions, root transforms, contacts, latents, the queries
    of its searches and its step times."""
    from lmm.runner import step_controllers

    n = int(round(seconds / dt))
    runs = {}
    for name, c in controllers.items():
        runs[name] = {"positions": np.zeros((n, c.db.n_bones, 3), np.float32), "root_position": np.zeros((n, 3)),
                      "root_rotation": np.zeros((n, 4)),
                      "rotations": np.zeros((n, c.db.n_bones, 4), np.float32), "contacts": np.zeros((n, 2), bool), "latents": [],
                      "queries": [], "step_us": np.zeros(n), "dt": dt, "frames": np.full(n, -1, np.int64)}
    for i in range(n):
        poses, snaps, ms = step_controllers(controllers, inputs.at(i * dt), dt)
        for name, run in runs.items():
            pose, snap = poses[name], snaps[name]
            run["step_us"][i] = ms[name] * 1e3
            run["positions"][i] = pose.global_positions
            run["rotations"][i] = pose.global_rotations
            run["root_position"][i] = pose.global_positions[0]
            run["root_rotation"][i] = pose.global_rotations[0]
            run["contacts"][i] = pose.contacts
            run["frames"][i] = snap.matched_frame
            if snap.latent is not None:
                run["latents"].append(snap.latent)
            if snap.searched:
                run["queries"].append(snap.query)
    for name, run in runs.items():
        run["latents"] = np.array(run["latents"]) if run["latents"] else None
        run["queries"] = np.array(run["queries"], np.float32).reshape(-1, controllers[name].features.n_dims)
    return runs


def run_controller(controller, inputs, seconds: float, dt: float = 1.0 / 60.0) -> dict:
    """:func:`run_controllers` for one controller."""
    return run_controllers({controller.name: controller}, inputs, seconds, dt)[controller.name]


def root_space(run: dict) -> np.ndarray:
    rel = run["positions"].astype(np.float64) - run["root_position"][:, None]
    return quat.inv_mul_vec(run["root_rotation"][:, None], rel)


def foot_skating_cm_s(run: dict, toe_bones) -> float:
    """Foot skating of a run by the one rule, :class:`lmm.metrics.FootSkating` (as ``lmm-studio run``)."""
    from lmm.metrics import FootSkating

    pos = run["positions"][:, toe_bones]
    skating = FootSkating()
    skating.add(pos[:-1], pos[1:], run["contacts"][1:], run["dt"])
    return skating.mean_cm_s()


def bone_length_error_m(run: dict, db) -> float:
    """Largest deviation of any bone length from the database skeleton's (m)."""
    ref = np.linalg.norm(db.positions[0, 1:].astype(np.float64), axis=-1)
    pos = run["positions"].astype(np.float64)
    parents = db.parents
    lengths = np.linalg.norm(pos[:, 2:] - pos[:, parents[2:]], axis=-1)
    return float(np.max(np.abs(lengths - ref[1:]))) if lengths.size else 0.0


def physics_of_runs(db, runs: dict) -> dict:
    """Per controller, the plausibility summary of its run (:mod:`lmm.physics.plausibility`): root residual
    force (body weights), penetration and sliding; ``{"available": False, "reason": ...}`` without mujoco."""
    from lmm.physics import PhysicsUnavailable, mujoco_available

    if not mujoco_available():
        return {"available": False, "reason": str(PhysicsUnavailable(f"the physics keys need mujoco: "
                                                                      f"pip install -e '.[physics]'"))}
    from lmm.physics.body import body_for_database
    from lmm.physics.plausibility import plausibility

    body = body_for_database(db)
    out: dict = {"available": True, "total_mass_kg": body.total_mass}
    for name, run in runs.items():
        result = plausibility(body, run["positions"].astype(np.float64), run["rotations"].astype(np.float64),
                              1.0 / run["dt"])
        out[name] = result.summary()
    return out


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
    runs = run_controllers({"mm": MotionMatchingController(db, features),
                            "lmm": LearnedMotionMatchingController(db, features, networks=nets,
                                                                   compare_with_search=False)}, log_in, seconds)
    mm, lmm = runs["mm"], runs["lmm"]
    dist = np.linalg.norm(root_space(mm) - root_space(lmm), axis=-1) * 100.0
    toes = [db.bone("left_toe"), db.bone("right_toe")]
    out["mm_vs_lmm"] = {"mean_joint_distance_cm": float(dist.mean()), "input": inputs, "seconds": seconds,
                        "root_distance_cm": float(np.mean(np.linalg.norm(mm["root_position"] - lmm["root_position"],
                                                                         axis=-1)) * 100.0)}
    out["projector"].update(projector_runtime_agreement(nets, features, mm["queries"]))
    out["foot_skating"] = {"mm_cm_s": foot_skating_cm_s(mm, toes), "lmm_cm_s": foot_skating_cm_s(lmm, toes)}
    from lmm.metrics import ground_skating, source_ground_skating
    out["ground_skating"] = {"mm": ground_skating(mm["positions"][:, toes], 1.0 / mm["dt"])["fraction"],
                             "lmm": ground_skating(lmm["positions"][:, toes], 1.0 / lmm["dt"])["fraction"],
                             "source": source_ground_skating(db)["fraction"]}
    from lmm.metrics import DurationStats
    from lmm.quality import PlayedAccelerations, QualityJoints, clip_quality, reference_quality
    joints, reference, played = QualityJoints.of_database(db), reference_quality(db), PlayedAccelerations(db)
    out["quality"] = {"database": reference, **{
        name: clip_quality(run["positions"], 1.0 / run["dt"], joints, reference, DurationStats, prefix="",
                           frames=run["frames"], played=played)
        for name, run in (("mm", mm), ("lmm", lmm))}}
    log("quality: " + "; ".join(
        f"{name} {q['pops_per_min']:.1f} pops/min, {q['knee_snaps_per_min']:.1f} knee snaps/min, jerk p99 "
        f"{q['jerk_p99_ratio']:.2f}x, low-speed acceleration p99 {q['acceleration_p99_slow_ratio']:.2f}x (the "
        f"frames played {q['acceleration_p99_slow_played_ratio']:.2f}x)"
        for name, q in ((n, out["quality"][n]) for n in ("mm", "lmm"))))
    out["physics"] = physics_of_runs(db, runs)
    if out["physics"].get("available"):
        log("physics: root residual force median " + ", ".join(
            f"{k} {out['physics'][k]['residual_force_bw_median']:.3f} BW" for k in ("mm", "lmm")))
    out["lmm_run"] = {"finite": bool(np.all(np.isfinite(lmm["positions"]))),
                      "max_bone_length_error_cm": bone_length_error_m(lmm, db) * 100.0,
                      "median_step_us": float(np.median(lmm["step_us"]))}
    log(f"mm vs lmm: mean joint distance {dist.mean():.2f} cm; foot skating mm {out['foot_skating']['mm_cm_s']:.2f} "
        f"lmm {out['foot_skating']['lmm_cm_s']:.2f} cm/s; ground skating mm {out['ground_skating']['mm']:.3f} "
        f"lmm {out['ground_skating']['lmm']:.3f} source {out['ground_skating']['source']:.3f} "
        f"({time.perf_counter() - t0:.1f} s)")
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

"""Training of the learned motion matching networks (torch; never imported by the runtime).

Three stages, as in the paper (Holden et al. 2020, Algorithms 1-3):

1. ``decompressor``: the compressor (training only) and the decompressor, trained jointly as an
   auto-encoder whose bottleneck is ``[matching features, latent]``; losses in local and character
   space (forward kinematics), their frame-to-frame changes, and latent regularisation.
2. ``stepper``: predicts the time derivative of ``[features, latent]``; trained by autoregressive rollout
   over a window of frames.
3. ``projector``: maps a (noisy) query to the ``[features, latent]`` of its exact nearest neighbour.

This module is the pipeline that trains the stages in order and writes the weights files; each stage's
loop is in its own module (``decompressor_training``, ``stepper_training``, ``projector_training``), the
data they share in ``training_data`` (numpy over all frames, done once; the loops index float32 tensors)
and the recipe, optimiser and loss log in ``training_loop``.
"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from lmm.features import Features
from lmm.nn import pose_vector_size
from lmm.offline.decompressor_training import compute_latents, make_autoencoder, train_decompressor
from lmm.offline.distributed import Parallel
from lmm.offline.networks import MLPSpec, NormalizedMLP
from lmm.offline.projector_training import train_projector
from lmm.offline.stepper_training import train_stepper
from lmm.offline.training_data import prepare
from lmm.offline.training_loop import LossLog, Recipe, StageSettings, auto_threads, interrupts_held

__all__ = ["COMPRESSOR_FILE", "LOG_FILE", "NETWORKS", "RUNTIME_FILE", "Recipe", "StageSettings", "train_pipeline"]

NETWORKS = ("decompressor", "stepper", "projector")


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
                   par: Parallel | None = None, verbose: bool = False) -> dict:
    """Train the given stages in order and write ``default.npz`` (decompressor, stepper, projector),
    ``compressor.npz`` and ``training_log.csv`` into ``out_dir``. Stages not trained are taken from
    the files already in ``out_dir``. ``resume``: stepper/projector start from the ones in ``out_dir``
    (a further schedule on top of a finished run) instead of from scratch. ``par``: the device and, under
    torchrun, the processes taking part (see :mod:`lmm.offline.distributed`; only rank 0 writes files).
    On ``stream``: a progress line per stage, or with ``verbose`` a loss line every ``recipe.log_every``
    iterations (the CSV's rows), nothing when ``quiet``. Returns a summary. Interrupted (Ctrl+C, SIGTERM),
    it writes one line saying where it stopped and which files ``out_dir`` holds, and re-raises; weights
    files are only ever replaced whole, together."""
    par = par or Parallel(torch.device("cpu"))
    recipe = recipe or Recipe()
    if not recipe.threads:
        recipe = replace(recipe, threads=auto_threads())
    stream = stream if stream is not None else sys.stderr
    torch.set_num_threads(recipe.threads)
    saved: list[str] = []
    LossLog.latest = None
    try:
        return _train(db, features, stages, recipe, Path(out_dir), frames, quiet, stream, resume, par, saved, verbose)
    except KeyboardInterrupt:
        if par.is_main:
            stream.write(interrupted_line(LossLog.latest, saved, out_dir) + "\n")
            stream.flush()
        raise


def interrupted_line(log: LossLog | None, saved: list[str], out_dir) -> str:
    """One line: the stage and iteration an interrupted training stopped at, and what ``out_dir`` holds."""
    if log is None:
        where = "before the first iteration"
    elif log.progress.count >= log.progress.total:
        where = f"after {log.network}'s {log.progress.total} iterations"
    else:
        log.close()   # ends the progress bar's line
        where = f"in {log.network} at iteration {log.progress.count} of {log.progress.total}"
    held = f"the weights there were saved at '{saved[-1]}'" if saved else "no weights were written by this run"
    return f"training stopped {where}; {held} ({out_dir})"


def check_stage_inputs(db, features: Features, out_dir: Path) -> None:
    """Raise the loader's one-line error when ``out_dir`` lacks the compressor a stage after the
    decompressor starts from (what :func:`_train` loads first)."""
    _load_networks(Path(out_dir) / COMPRESSOR_FILE, ["compressor"], db, features)


def _train(db, features, stages, recipe, out_dir, frames, quiet, stream, resume, par, saved, verbose) -> dict:
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
        with interrupts_held():   # the compressor and the runtime weights belong together: both or neither
            if "compressor" in nets:
                _save_networks(comp_path, {"compressor": nets["compressor"]}, meta, extra)
                if runtime:
                    z = compute_latents(nets["compressor"], data).numpy()
                    extra["latent_mean"] = [float(v) for v in z.mean(0)]
                    extra["latent_std"] = [float(v) for v in z.std(0)]
            if runtime:
                _save_networks(runtime_path, runtime, meta, extra)
            saved.append(note)

    if "decompressor" in stages:
        s = recipe.decompressor
        t0 = time.perf_counter()
        torch.manual_seed(recipe.seed)  # the initial weights, too, follow the seed
        pair = make_autoencoder(data, recipe.latent, recipe.hidden)
        nets["compressor"], nets["decompressor"] = pair

        def checkpoint(it):
            save_all(f"checkpoint: decompressor at iteration {it}/{s.iterations}")

        _, _, log = train_decompressor(data, s, recipe.seed, recipe.latent, recipe.hidden, recipe.log_every,
                                       csv_path, quiet, stream, verbose, networks=pair,
                                       checkpoint=None if frames is not None else checkpoint, par=par)
        wall["decompressor"] = round(time.perf_counter() - t0, 1)
        summary["first_loss"]["decompressor"], summary["final_loss"]["decompressor"] = log.first_loss, log.last_loss
        save_all("after decompressor")
    Z = compute_latents(nets["compressor"], data)
    if "stepper" in stages:
        t0 = time.perf_counter()
        nets["stepper"], log = train_stepper(data, Z, recipe.stepper, recipe.stepper_window, recipe.seed, recipe.hidden,
                                             recipe.log_every, csv_path, quiet, stream, verbose,
                                             stepper=nets.get("stepper") if resume else None,
                                             log_name="stepper_resumed" if resume else "stepper", par=par)
        wall["stepper" + ("_resumed" if resume else "")] = round(time.perf_counter() - t0, 1)
        summary["first_loss"]["stepper"], summary["final_loss"]["stepper"] = log.first_loss, log.last_loss
        save_all("after stepper")
    if "projector" in stages:
        t0 = time.perf_counter()
        nets["projector"], log = train_projector(data, Z, recipe.projector, recipe.seed, recipe.hidden,
                                                 recipe.log_every, csv_path, quiet, stream, verbose,
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

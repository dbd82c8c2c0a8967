"""Building the motion database from a manifest, in the order of the reference pipeline:
BVH -> local rotations/positions (unit scaled) -> trim to ranges -> cubic resample to the target fps
-> left/right mirror copy -> prepend the simulation (root) bone -> velocities and angular velocities
-> foot contacts (the maths: :mod:`lmm.data.preparation`). Takes are built one at a time, or side by
side in worker processes; either way the database is the same bit for bit. :func:`load_or_build` reads
the cache (:mod:`lmm.data.cache`) or builds and writes it. A build stops with a ManifestError before
resampling a range that would take the database past :data:`MAX_DATABASE_FRAMES` frames.
"""
from __future__ import annotations

import contextlib
import os
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from lmm import DEFAULT_MANIFEST, quat
from lmm.data import bvh
from lmm.data.motion_files import load_motion
from lmm.data.cache import build_code_fingerprint, cache_file_name, default_cache_dir, manifest_key
from lmm.data.database import Database, DatabaseError
from lmm.data.derived import derived_dir_of
from lmm.data.leftovers import die_with_parent, remove_stale, remove_stale_spills, spill_folder
from lmm.skeleton import SIMULATION_BONE
from lmm.data.manifest import Manifest, ManifestError, load_manifest
from lmm.data.preparation import (foot_contacts, mirror_local, mirror_map, quat_central_difference, resample,
                                  resampled_length, simulation_bone)
from lmm.filters import central_difference
from lmm.kinematics import forward_kinematics

#: Most frames in a built database (mirrored copies included): 4.6 hours at 60 fps, twice every take of
#: the LAFAN1 folder mirrored (501,918 frames) and 17x the shipped set (57,500). The build works one take
#: at a time (a few hundred MB at its peak for the longest take) and writes about 1.2 KB a frame (23
#: bones) to the cache, which the runtime memory-maps: 1.2 GB of cache at this limit.
MAX_DATABASE_FRAMES = 1_000_000
#: Fewest frames in a range after resampling: the velocities and the trajectory features need them.
MIN_RANGE_FRAMES = 4


def database_range_tags(manifest: Manifest) -> list[tuple[str, ...]]:
    """The tags of every database range in build order (each range, then its mirror when mirrored)."""
    out = []
    for clip in manifest.clips:
        for k in range(len(clip.ranges or [None])):
            out += [clip.tags_of(k)] * (2 if manifest.mirror else 1)
    return out

#: Most worker processes a build uses (one take each at a time; a few hundred MB each at the peak).
MAX_BUILD_WORKERS = 4


@dataclass
class _Piece:
    """One finished database range (float32 as stored), made from one range of one take."""
    name: str
    mirrored: bool
    positions: np.ndarray
    rotations: np.ndarray
    velocities: np.ndarray
    angular_velocities: np.ndarray
    contacts: np.ndarray
    toe_speeds: np.ndarray


@dataclass
class _Take:
    """What one take adds to the database: its skeleton, its ranges' frame counts and its pieces."""
    names: list[str]
    parents: np.ndarray
    n_frames: int          # frames it adds (mirrored copies included)
    pieces: list[_Piece]


def _finish_piece(name: str, is_mirror: bool, rot, pos, parents, manifest: Manifest, names,
                  global_transforms=None) -> _Piece:
    """A resampled range -> the stored range: simulation bone, velocities, contacts (float32).
    ``global_transforms``: ``forward_kinematics(rot, pos, parents)`` when the caller has it."""
    hips, spine = names.index(manifest.bones["hips"]), names.index(manifest.bones["spine"])
    toes = [names.index(manifest.bones["left_toe"]), names.index(manifest.bones["right_toe"])]
    dt = 1.0 / manifest.target_fps
    g_rot, g_pos = global_transforms or forward_kinematics(rot, pos, parents)
    sim_rot, sim_pos = simulation_bone(g_rot, g_pos, spine, hips, manifest.hips_forward_axis, manifest)
    # re-parent every root of the file under the simulation bone
    rot = rot.copy()
    pos = pos.copy()
    for j in np.where(parents < 0)[0]:
        rot[:, j] = quat.inv_mul(sim_rot, rot[:, j])
        pos[:, j] = quat.inv_mul_vec(sim_rot, pos[:, j] - sim_pos)
    full_rot = quat.unroll(np.concatenate([sim_rot[:, None], rot], axis=1), axis=0)
    full_pos = np.concatenate([sim_pos[:, None], pos], axis=1)
    speeds = np.stack([foot_contacts(g_pos[:, t], dt, manifest.contact_speed_threshold_m_s,
                                     manifest.contact_median_window)[1] for t in toes], axis=-1).astype(np.float32)
    return _Piece(
        name=name, mirrored=is_mirror,
        positions=full_pos.astype(np.float32), rotations=full_rot.astype(np.float32),
        velocities=central_difference(full_pos, dt).astype(np.float32),
        angular_velocities=quat_central_difference(full_rot, dt).astype(np.float32),
        # threshold the stored float32 speeds so the invariant holds exactly on what is saved
        contacts=speeds < np.float32(manifest.contact_speed_threshold_m_s), toe_speeds=speeds)


#: shortest leg bone accepted (metres): the leg IK divides by the thigh, shin and foot lengths
MIN_LEG_BONE_M = 1e-4


def _check_bone_lengths(offsets, names, parents, manifest: Manifest, ci: int) -> None:
    """Refuse a degenerate skeleton in one line: every joint at its parent's place (all OFFSETs 0), or
    a leg bone (hip to knee, knee to ankle, ankle to toe) of zero length, which the runtime's IK divides
    by (a legal take with every OFFSET 0 built, then ``run`` died in ik.py with ZeroDivisionError).
    ``offsets``: the first frame's local positions in metres (position channels included)."""
    where, name = f"clips[{ci}].file", manifest.clips[ci].file.name
    if not np.any(np.abs(offsets[parents >= 0]) > 0.0):
        raise ManifestError(manifest.path, where, f"{name}: every joint OFFSET is 0 (all joints at one point): "
                                                  f"not a usable skeleton")
    for side in ("left", "right"):
        if f"{side}_foot" not in manifest.bones or f"{side}_toe" not in manifest.bones:
            continue
        foot, toe = names.index(manifest.bones[f"{side}_foot"]), names.index(manifest.bones[f"{side}_toe"])
        knee = int(parents[foot])
        for joint in (knee, foot, toe):
            if joint > 0 and float(np.linalg.norm(offsets[joint])) < MIN_LEG_BONE_M:
                raise ManifestError(manifest.path, where, f"{name}: the bone to {names[joint]!r} has length "
                                                          f"{np.linalg.norm(offsets[joint]):.3g} m, shorter than "
                                                          f"{MIN_LEG_BONE_M:g} m: the leg IK needs its length")


def _build_take(manifest: Manifest, ci: int, skeleton=None, frames_before: int = 0) -> _Take:
    """Take ``ci`` of the manifest as database ranges, checked in the build's order: its file, its
    skeleton (against ``skeleton``, the first take's (names, parents), or the bone roles when None),
    then each range (bounds, length, the database frame limit counting ``frames_before``)."""
    mpath = manifest.path
    clip = manifest.clips[ci]
    copies = 2 if manifest.mirror else 1
    try:
        anim = load_motion(clip.file)  # BVHError names the file and line (BVH, glTF or FBX)
    except OSError as e:
        raise ManifestError(mpath, f"clips[{ci}].file",
                            f"cannot read {clip.file}: {e.strerror or type(e).__name__}") from None
    names, parents = list(anim.names), np.asarray(anim.parents, dtype=np.int64)
    if skeleton is None:
        for role, bone_name in manifest.bones.items():
            if bone_name not in names:
                raise ManifestError(mpath, f"bones.{role}",
                                    f"joint {bone_name!r} not in {clip.file.name} (joints: {', '.join(names)})")
    elif names != skeleton[0] or not np.array_equal(parents, skeleton[1]):
        raise ManifestError(mpath, f"clips[{ci}].file",
                            f"{clip.file.name} has a different skeleton from {manifest.clips[0].file.name}")
    mirror_idx = mirror_map(names, manifest.mirror_name_pairs)
    local_rot = anim.local_rotations()
    local_pos = anim.local_positions() * manifest.unit_scale
    _check_bone_lengths(local_pos[0], names, parents, manifest, ci)
    source_fps = 1.0 / anim.frame_time
    if abs(source_fps - round(source_fps)) < 0.01:
        source_fps = float(round(source_fps))  # "Frame Time: 0.033333" means 30 fps, not 30.0003
    ranges = clip.ranges or [(0, anim.n_frames)]
    pieces = []
    total_frames = frames_before
    for ri, (start, stop) in enumerate(ranges):
        if stop > anim.n_frames:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]",
                                f"stop {stop} is past the last frame of {clip.file.name} ({anim.n_frames} frames)")
        if stop - start < MIN_RANGE_FRAMES:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]", "a range needs at least 4 frames")
        n_out = resampled_length(stop - start, source_fps, manifest.target_fps, manifest.speed_scale)
        if n_out < MIN_RANGE_FRAMES:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]",
                                f"{stop - start} frames at {source_fps:g} fps make {n_out} at target_fps "
                                f"{manifest.target_fps:g} (speed_scale {manifest.speed_scale:g}): a range "
                                f"needs at least {MIN_RANGE_FRAMES} frames")
        total_frames += n_out * copies
        if total_frames > MAX_DATABASE_FRAMES:
            raise ManifestError(mpath, f"clips[{ci}].ranges[{ri}]",
                                f"the database would pass {MAX_DATABASE_FRAMES} frames here (at target_fps "
                                f"{manifest.target_fps:g}, speed_scale {manifest.speed_scale:g}"
                                f"{', mirrored' if manifest.mirror else ''}): use fewer or shorter ranges")
        rot, pos = resample(quat.unroll(local_rot[start:stop]), local_pos[start:stop], source_fps,
                            manifest.target_fps, manifest.speed_scale)
        base = f"{clip.file.name.split('.')[0]}[{start}:{stop}]"
        # the range's forward kinematics, once for the piece and its mirrored copy
        global_transforms = forward_kinematics(rot, pos, parents)
        pieces.append(_finish_piece(base, False, rot, pos, parents, manifest, names, global_transforms))
        if manifest.mirror:
            mrot, mpos = mirror_local(rot, pos, parents, mirror_idx, global_transforms)
            pieces.append(_finish_piece(base + " mirrored", True, quat.unroll(mrot), mpos, parents, manifest, names))
    return _Take(names, parents, total_frames - frames_before, pieces)


#: the arrays of a :class:`_Piece` (the rest are its name and mirror flag)
_PIECE_ARRAYS = ("positions", "rotations", "velocities", "angular_velocities", "contacts", "toe_speeds")


def _build_take_or_none(job) -> _Take | None:
    """A worker's job: the take, or None when it fails (the build then redoes it in order to raise the
    very error a one-process build raises). With a spill folder the pieces' arrays are written there as
    ``.npy`` files and the take comes back holding their paths (see :func:`_unspill`): a long take's
    arrays are tens of MB, and pickling them through the pool's pipe cost the parent process about 4 s
    of CPU for the 0.5 M-frame set, against a read of files the page cache still holds."""
    manifest, ci, spill = job
    try:
        take = _build_take(manifest, ci)
        if spill is not None:
            for k, piece in enumerate(take.pieces):
                for name in _PIECE_ARRAYS:
                    path = os.path.join(spill, f"{ci}-{k}-{name}.npy")
                    np.save(path, getattr(piece, name), allow_pickle=False)
                    setattr(piece, name, path)
        return take
    except Exception:
        return None


def _unspill(take: _Take | None) -> _Take | None:
    """A worker's take with its spilled arrays read back (memory maps of the files)."""
    if take is not None:
        for piece in take.pieces:
            for name in _PIECE_ARRAYS:
                value = getattr(piece, name)
                if isinstance(value, str):
                    setattr(piece, name, np.load(value, mmap_mode="r", allow_pickle=False))
    return take


def build_workers(manifest: Manifest) -> int:
    """Worker processes worth using for a build: one per core (at most :data:`MAX_BUILD_WORKERS`), none
    for one take."""
    n = min(MAX_BUILD_WORKERS, os.cpu_count() or 1, len(manifest.clips))
    return n if n > 1 else 0


def _takes(manifest: Manifest, workers: int, spill: str | None = None):
    """The takes in manifest order, each checked exactly as a one-process build checks it. With
    ``workers`` > 0 they are built in that many processes, ahead of the order (their arrays passed
    through files in the folder ``spill`` when given, see :func:`_build_take_or_none`); a take that
    failed there or breaks a cross-take rule is built again here, which raises."""
    skeleton, total = None, 0
    workers = min(workers, len(manifest.clips))
    if workers <= 1:
        for ci in range(len(manifest.clips)):
            take = _build_take(manifest, ci, skeleton, total)
            skeleton, total = skeleton or (take.names, take.parents), total + take.n_frames
            yield take
        return
    import multiprocessing

    # fork where there is one: no re-import of the caller's main module (spawn's) is needed
    method = "fork" if "fork" in multiprocessing.get_all_start_methods() else "spawn"
    with multiprocessing.get_context(method).Pool(workers, initializer=die_with_parent) as pool:
        jobs = [(manifest, ci, spill) for ci in range(len(manifest.clips))]
        for ci, take in enumerate(map(_unspill, pool.imap(_build_take_or_none, jobs))):
            if (take is None or total + take.n_frames > MAX_DATABASE_FRAMES
                    or (skeleton is not None and (take.names != skeleton[0]
                                                  or not np.array_equal(take.parents, skeleton[1])))):
                take = _build_take(manifest, ci, skeleton, total)  # raises the build's own error
            skeleton, total = skeleton or (take.names, take.parents), total + take.n_frames
            yield take


def build(manifest: Manifest, progress=None, workers: int = 0) -> Database:
    """Build the database from a parsed manifest. ``progress(done, total, label)`` is called per range.
    ``workers``: processes that build takes side by side (0: this process only; see :func:`build_workers`),
    for single-threaded callers such as ``lmm-studio build-db`` (forking a process that runs threads, a GUI,
    is not safe); the database is the same bit for bit either way."""
    total_ranges = sum(len(c.ranges) if c.ranges else 1 for c in manifest.clips) * (2 if manifest.mirror else 1)
    workers = min(workers, len(manifest.clips))
    # the workers' arrays come back through files here (removed once joined into the database's arrays)
    spill = spill_folder() if workers > 1 else contextlib.nullcontext(None)
    with spill as spill_dir:
        names = parents = None
        pieces: list[_Piece] = []
        for take in _takes(manifest, workers, spill_dir):
            names, parents = names or take.names, take.parents if parents is None else parents
            for piece in take.pieces:
                pieces.append(piece)
                if progress:
                    progress(len(pieces), total_ranges, piece.name)

        all_names = [SIMULATION_BONE] + names
        all_parents = np.concatenate([[-1], np.where(parents < 0, 0, parents + 1)]).astype(np.int64)
        lengths = np.array([p.positions.shape[0] for p in pieces], dtype=np.int64)
        stops = np.cumsum(lengths)
        mirror_full = np.concatenate([[0], mirror_map(names, manifest.mirror_name_pairs) + 1]).astype(np.int64)

        def joined(field_name):
            return np.concatenate([getattr(p, field_name) for p in pieces])

        db = Database(
            names=all_names, parents=all_parents,
            positions=joined("positions"), rotations=joined("rotations"), velocities=joined("velocities"),
            angular_velocities=joined("angular_velocities"), contacts=joined("contacts").astype(bool),
            toe_speeds=joined("toe_speeds"),
            range_starts=stops - lengths, range_stops=stops,
            range_names=[p.name for p in pieces], range_mirrored=np.array([p.mirrored for p in pieces], dtype=bool),
            fps=float(manifest.target_fps), bone_roles=dict(manifest.bones), mirror_map=mirror_full,
            key=manifest_key(manifest), name=manifest.name, build_fingerprint=build_code_fingerprint())
        pieces.clear()  # the files' maps closed before the folder goes
    db.set_tags(database_range_tags(manifest))
    set_feature_schema(db, manifest)
    return db


def set_feature_schema(db: Database, manifest: Manifest) -> None:
    """Give ``db`` the manifest's feature schema, checking that every channel's bone exists."""
    for i, ch in enumerate(manifest.features):
        if ch.get("bone") is not None:
            try:
                db.bone(ch["bone"])
            except KeyError:
                roles = ", ".join(sorted(db.bone_roles))
                raise ManifestError(manifest.features_file or manifest.path, f"features[{i}].bone",
                                    f"no joint or role named {ch['bone']!r} (roles: {roles})") from None
    db.feature_schema = [dict(ch) for ch in manifest.features]

@dataclass
class LoadInfo:
    path: Path | None     # the database file read or written; None when it could not be saved
    cached: bool
    seconds: float
    not_saved: str = ""   # why a built database could not be cached (a read-only cache folder...)


def load_or_build(manifest_path=None, cache_dir=None, progress=None, rebuild: bool = False,
                  out_path=None, workers: int = 0, before_save=None) -> tuple[Database, LoadInfo]:
    """The database for a manifest, from the cache when its key matches, else built (``workers``: see
    :func:`build`) and cached.

    With ``out_path`` the database is written there and a failure to write it is an ``OSError`` (the
    caller asked for that file); a cache that cannot be written is only reported in ``LoadInfo``.
    ``before_save(db, path)``, when given, is called after a build, before the file is written (the
    caller may start work that needs the database and the path, e.g. its derived arrays, meanwhile)."""
    t0 = time.perf_counter()
    manifest = load_manifest(manifest_path or DEFAULT_MANIFEST)
    key = manifest_key(manifest)
    path = Path(out_path) if out_path else Path(cache_dir or default_cache_dir()) / cache_file_name(key)
    remove_stale(path.parent)   # half-written files and spill folders of killed processes (never of running ones)
    remove_stale(derived_dir_of(path))
    remove_stale_spills()
    if not rebuild and path.is_file():
        try:
            db = Database.load(path)
            if db.key == key and db.build_fingerprint == build_code_fingerprint():
                tags = database_range_tags(manifest)
                # retagged manifest or a new feature schema: same frames, so the cache is updated in place
                # (the key, and the networks trained on these frames, stay valid; networks trained on
                # another schema are refused by lmm.data.weights with what differs)
                if db.range_tags != tags or db.feature_schema != manifest.features:
                    db.set_tags(tags)
                    set_feature_schema(db, manifest)
                    try:
                        db.save(path)
                    except OSError:
                        pass
                return db, LoadInfo(path, True, time.perf_counter() - t0)
        except DatabaseError as e:   # damaged, hand-made or of another format: never trusted, built again
            print(f"note: {one_line_of(e)}; building the database again", file=sys.stderr)
    db = build(manifest, progress=progress, workers=workers)
    if before_save is not None:
        before_save(db, path)
    if out_path:
        db.save(path)  # atomic: an OSError leaves no file behind, and the caller reports it
        db.source_path = path
        return db, LoadInfo(path, False, time.perf_counter() - t0)
    try:
        db.save(path)
    except OSError as e:  # a read-only or full cache location must not stop the tool
        return db, LoadInfo(None, False, time.perf_counter() - t0,
                            not_saved=f"cannot write the cache {path}: {e.strerror or type(e).__name__}")
    db.source_path = path  # its derived arrays are cached beside the file (lmm.data.derived)
    return db, LoadInfo(path, False, time.perf_counter() - t0)


def one_line_of(e: Exception) -> str:
    return " ".join(str(e).split())[:300]


def manifest_inputs(manifest_path=None) -> list[tuple[str, Path]]:
    """The files a build reads, as ``(field, path)`` pairs (the manifest, its feature schema file, each
    clip): what no output of the same command may overwrite (:func:`lmm.data.outputs.check_outputs`)."""
    manifest = load_manifest(manifest_path or DEFAULT_MANIFEST)
    files = [("--manifest", manifest.path)]
    if manifest.features_file is not None:
        files.append(("features", manifest.features_file))
    return files + [(f"clips[{i}]", clip.file) for i, clip in enumerate(manifest.clips)]


def load_default(progress=None) -> Database:
    return load_or_build(progress=progress)[0]

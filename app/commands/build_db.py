"""``lmm-studio build-db``: build the motion database (or load it from the cache) and report its size."""
from __future__ import annotations

import sys


def add_arguments(p) -> None:
    p.add_argument("--manifest", help="dataset manifest (JSON or TOML); default: the shipped LAFAN1 locomotion set")
    p.add_argument("--out", help="write the database .npz here instead of the cache folder")
    p.add_argument("--rebuild", action="store_true", help="ignore the cache and build again")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--no-checks", action="store_true", help="skip the data checks (see check-data)")
    p.add_argument("--jobs", type=int, default=None, metavar="N",
                   help="processes that build takes side by side (default: one per core, at most 4; 1: none)")


def _error(message: str) -> None:
    print(f"lmm-studio build-db: error: {message}", file=sys.stderr)


def _os_error_line(e: OSError, out) -> str:
    """An OSError as one line naming the file asked for (not a temporary name or a parent folder)."""
    target = out if out else e.filename
    reason = e.strerror or str(e) or type(e).__name__
    return f"cannot write {target}: {reason}" if target is not None else reason


def main(args) -> int:
    import os

    from lmm.data.database import MAX_BUILD_WORKERS, load_or_build
    from lmm.errors import InputError
    from lmm.progress import ProgressCallback

    if args.jobs is not None and args.jobs < 1:
        _error(f"--jobs must be at least 1, got {args.jobs}")
        return 1
    jobs = args.jobs if args.jobs is not None else min(MAX_BUILD_WORKERS, os.cpu_count() or 1)

    progress = ProgressCallback("build-db", quiet=args.quiet)
    try:
        # one process needs no workers; more build takes side by side (same database bit for bit)
        db, info = load_or_build(args.manifest, progress=progress, rebuild=args.rebuild, out_path=args.out,
                                 workers=jobs if jobs > 1 else 0)
    except InputError as e:  # a bad manifest, take or field: the line names the file and field
        _error(str(e))
        return 1
    except OSError as e:  # --out not writable (read-only folder, full disk): nothing was written there
        _error(_os_error_line(e, args.out))
        return 1
    finally:
        progress.close()
    checks = None if args.no_checks else _start_checks(args.manifest, jobs)
    if info.path is not None:
        _precompute_derived(db)
    source = "cache" if info.cached else "built"
    print(f"database  {db.name} ({source} in {info.seconds:.2f} s)")
    print(f"file      {info.path}" if info.path is not None else f"file      not saved ({info.not_saved})")
    print(f"clips     {db.n_ranges} ranges ({int(db.range_mirrored.sum())} mirrored)")
    print(f"frames    {db.n_frames} at {db.fps:g} fps")
    print(f"seconds   {db.seconds:.1f}")
    print(f"bones     {db.n_bones}")
    print(f"bytes     {db.pose_bytes()} ({db.pose_bytes() / 2**20:.1f} MiB pose data)")
    if checks is not None:
        _print_warnings(checks)
    return 0


def _precompute_derived(db) -> None:
    """Fill the per-database cache beside the file (features, root velocities, contact heights, start
    frame, source skating; see lmm/data/derived.py) so the first run does not read every frame."""
    from lmm.character import range_contact_heights, root_local_velocities
    from lmm.features import build_features
    from lmm.metrics import source_ground_skating
    from lmm.mm import default_start_frame

    build_features(db)
    root_local_velocities(db)
    range_contact_heights(db, [db.bone("left_toe"), db.bone("right_toe")])
    default_start_frame(db)
    source_ground_skating(db)


def _warning_lines(manifest_path) -> list[str]:
    """The data checks' findings inside ranges the database uses, one warning line each."""
    from lmm import DEFAULT_MANIFEST
    from lmm.data.checks import CheckError, check_manifest
    from lmm.data.manifest import ManifestError, load_manifest

    try:
        findings, _ = check_manifest(load_manifest(manifest_path or DEFAULT_MANIFEST))
    except (ManifestError, CheckError) as e:
        return [f"warning: data checks skipped: {e}"]
    return [f"warning: {f.line()}" for f in findings if f.in_used_range]


def _start_checks(manifest_path, jobs: int):
    """The data checks' warning lines, as a call that returns them: with cores to spare the checks run
    in a second process meanwhile (while this one fills the derived-array cache), else at the call."""
    import multiprocessing

    if jobs < 2 or "fork" not in multiprocessing.get_all_start_methods():
        return lambda: _warning_lines(manifest_path)
    from concurrent.futures import ProcessPoolExecutor

    pool = ProcessPoolExecutor(1, mp_context=multiprocessing.get_context("fork"))
    future = pool.submit(_warning_lines, manifest_path)

    def result() -> list[str]:
        try:
            return future.result()
        finally:
            pool.shutdown()
    return result


def _print_warnings(checks) -> None:
    for line in checks():
        print(line, file=sys.stderr)

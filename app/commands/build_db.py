"""``lmm-studio build-db``: build the motion database (or load it from the cache) and report its size."""
from __future__ import annotations

import sys


#: data-check warnings build-db prints by default (the rest are counted; check-data lists them all)
LISTED_WARNINGS = 8


def add_arguments(p) -> None:
    p.add_argument("--manifest", help="dataset manifest (JSON or TOML); default: the shipped LAFAN1 locomotion set")
    p.add_argument("--out", help="write the database .npz here instead of the cache folder")
    p.add_argument("--rebuild", action="store_true", help="ignore the cache and build again")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--no-checks", action="store_true", help="skip the data checks (see check-data)")
    p.add_argument("--verbose", action="store_true",
                   help=f"print every data-check warning (default: the first {LISTED_WARNINGS} and a count)")
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

    from lmm.data.build import MAX_BUILD_WORKERS, load_or_build
    from lmm.errors import InputError
    from lmm.progress import ProgressCallback

    if args.jobs is not None and args.jobs < 1:
        _error(f"--jobs must be at least 1, got {args.jobs}")
        return 1
    jobs = args.jobs if args.jobs is not None else min(MAX_BUILD_WORKERS, os.cpu_count() or 1)

    progress = ProgressCallback("build-db", quiet=args.quiet)
    derived = _DerivedBeside(jobs)
    checks = None

    def before_save(db, path):
        # while the database file is written: its derived arrays and the data checks in other processes
        nonlocal checks
        derived.start(db, path)
        if not args.no_checks:
            checks = _start_checks(args.manifest, jobs)

    try:
        if args.out:   # never over the manifest or one of its takes
            from lmm.data.build import manifest_inputs
            from lmm.data.outputs import check_outputs
            check_outputs([("--out", args.out)], manifest_inputs(args.manifest))
        # one process needs no workers; more build takes side by side (same database bit for bit)
        db, info = load_or_build(args.manifest, progress=progress, rebuild=args.rebuild, out_path=args.out,
                                 workers=jobs if jobs > 1 else 0, before_save=before_save)
    except InputError as e:  # a bad manifest, take or field: the line names the file and field
        _error(str(e))
        return 1
    except OSError as e:  # --out not writable (read-only folder, full disk): nothing was written there
        derived.discard()
        if checks is not None:
            checks.cancel()
        _error(_os_error_line(e, args.out))
        return 1
    finally:
        progress.close()
    if checks is None and not args.no_checks:
        checks = _start_checks(args.manifest, jobs)
    if info.path is None:
        derived.discard()
    elif not derived.finish():
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
        _print_warnings(checks, every=args.verbose)
    from lmm.data_fit import fit_warnings
    from lmm.tuning import Tuning

    for line in fit_warnings(db, Tuning()):   # speeds the default tuning asks for, bone roles that look wrong
        print(f"warning: {line}", file=sys.stderr)
    return 0


class _DerivedBeside:
    """The derived arrays of a database just built, computed in a second process while this one writes
    the database file (``start`` is :func:`lmm.data.build.load_or_build`'s ``before_save``): writing
    600 MB and filling the cache were one after the other before (about 2 s and 5 s for the 0.5 M-frame
    set). Only with cores to spare and ``fork`` (the child reads the database this process holds)."""

    def __init__(self, jobs: int):
        self.jobs, self.process, self.folder = jobs, None, None

    def start(self, db, path) -> None:
        import multiprocessing

        if self.jobs < 2 or "fork" not in multiprocessing.get_all_start_methods():
            return
        from lmm.data.derived import derived_dir_of

        def run():
            from lmm.data.leftovers import die_with_parent
            die_with_parent()   # never outlives a killed build-db
            db.source_path = path
            _precompute_derived(db)

        self.folder = derived_dir_of(path)
        self.process = multiprocessing.get_context("fork").Process(target=run, name="build-db-derived")
        self.process.start()

    def finish(self) -> bool:
        """Wait for the second process: True when it filled the cache."""
        if self.process is None:
            return False
        self.process.join()
        return self.process.exitcode == 0

    def discard(self) -> None:
        """The database file was not written: stop and remove what the second process wrote beside it."""
        if self.process is None:
            return
        import shutil

        self.process.terminate()
        self.process.join()
        shutil.rmtree(self.folder, ignore_errors=True)


def _precompute_derived(db) -> None:
    """Fill the per-database cache beside the file (features, root velocities, contact heights, start
    frame, source skating; see lmm/data/derived.py) so the first run does not read every frame."""
    from lmm.ground import range_contact_heights
    from lmm.source_pose import root_local_velocities
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
    from lmm.checks import CheckError, check_manifest
    from lmm.data.manifest import ManifestError, load_manifest

    try:
        findings, _ = check_manifest(load_manifest(manifest_path or DEFAULT_MANIFEST))
    except (ManifestError, CheckError) as e:
        return [f"warning: data checks skipped: {e}"]
    return [f"warning: {f.line()}" for f in findings if f.in_used_range]


def _start_checks(manifest_path, jobs: int):
    """The data checks' warning lines, as a call that returns them: with cores to spare the checks run
    in another process meanwhile (while this one writes the database file), else at the call. The call
    has ``cancel()``, which stops that process (a build that failed prints no warnings)."""
    import multiprocessing

    if jobs < 2 or "fork" not in multiprocessing.get_all_start_methods():
        def now() -> list[str]:
            return _warning_lines(manifest_path)
        now.cancel = lambda: None
        return now
    # a plain process and a pipe: no helper thread in this process, which may fork again
    ctx = multiprocessing.get_context("fork")
    receive, send = ctx.Pipe(duplex=False)

    def run():
        from lmm.data.leftovers import die_with_parent
        die_with_parent()
        try:
            lines = _warning_lines(manifest_path)
        except Exception as e:  # noqa: BLE001 - a failed check is reported, never fatal to the build
            lines = [f"warning: data checks failed: {type(e).__name__}: {e}"]
        send.send(lines)

    process = ctx.Process(target=run, name="build-db-checks", daemon=True)
    process.start()
    send.close()

    def result() -> list[str]:
        try:
            return receive.recv()
        except EOFError:
            return [f"warning: data checks stopped (exit code {process.exitcode})"]
        finally:
            process.join()
    result.cancel = process.terminate
    return result


def _print_warnings(checks, every: bool = False) -> None:
    """The data checks' lines on stderr: the first :data:`LISTED_WARNINGS` and how many more, or all."""
    lines = checks()
    shown = lines if every else lines[:LISTED_WARNINGS]
    for line in shown:
        print(line, file=sys.stderr)
    if len(lines) > len(shown):
        print(f"warning: {len(lines) - len(shown)} more data-check findings inside used ranges (--verbose, or "
              f"lmm-studio check-data --used-only --verbose, lists them)", file=sys.stderr)

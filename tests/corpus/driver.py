"""Run corpus cases in this one process and report each as a JSON line (see tests/corpus/corpus_harness.py).

    python tests/corpus/driver.py RESULTS.jsonl CASES.json MEM_CAP_BYTES STOP_ABOVE_BYTES

Each case calls ``app.cli.main(argv)`` (``call: cli``), ``lmm.data.bvh.load`` (``reader``) or
``app.layout_files.load`` (``layout``) with file descriptors 1 and 2 redirected to files, so output from
Python and from C libraries is both captured. An exception escaping the call is what a real run would
show as a traceback: it is reported as ``uncaught``. Before a case: ``{"start": id}``; after it: the
result. The process stops after a case that pushed its peak resident memory above STOP_ABOVE_BYTES, so
the harness can attribute memory to one case and go on in a fresh process. A case may carry ``before``
and ``after`` specs (tests/corpus/state_cases.py: the state it reads, the output it must leave) and
``no_passwd`` (run as a uid without passwd entry).
"""
from __future__ import annotations

import json
import os
import re
import resource
import sys
import tempfile
import time
import traceback
import warnings
from pathlib import Path

OUTPUT_LIMIT = 64 * 1024  # bytes of stdout/stderr kept per case


def _input_error_types(module_error):
    types = [module_error]
    try:
        from lmm.errors import InputError  # the shared contract (may not exist yet on every branch)
        types.append(InputError)
    except ImportError:
        pass
    return tuple(types)


def _call(case: dict):
    """-> (rc, extra dict). rc: int exit status; raises whatever the call lets escape."""
    call = case["call"]
    if call == "cli":
        from app.cli import main
        try:
            return int(main(list(case["argv"])) or 0), {}
        except SystemExit as e:  # argparse (2), sys.exit(...) inside a command
            code = e.code
            if code is None:
                return 0, {}
            if isinstance(code, int):
                return code, {}
            print(code, file=sys.stderr)  # sys.exit("message") prints the message, status 1
            return 1, {}
    if call == "reader":
        from lmm.data import bvh
        try:
            anim = bvh.load(case["path"])
            anim.global_positions()
        except _input_error_types(bvh.BVHError) as e:
            print(str(e), file=sys.stderr)
            return 1, {"error_type": type(e).__name__}
        return 0, {"frames": int(anim.n_frames)}
    if call == "layout":
        from app import layout_files
        try:
            layout = layout_files.load(case["path"])
        except _input_error_types(layout_files.LayoutError) as e:
            print(str(e), file=sys.stderr)
            return 1, {"error_type": type(e).__name__}
        numbers = [v for rect in layout.windows.values() for k in ("pos", "size") if rect.get(k) is not None
                   for v in rect[k]]
        return 0, {"layout": {"windows": {k: {"pos": r.get("pos"), "size": r.get("size")}
                                          for k, r in layout.windows.items()},
                              "reference_size": list(layout.reference_size),
                              "numbers_are_ints": all(isinstance(v, int) for v in numbers)}}
    raise ValueError(f"unknown call {call!r}")


# the cache's own subfolders: trace logs, the motion search index, the compiled search filter (named by
# its source's hash), a database's derived arrays (named by the database's hash, never by user text)
_CACHE_SUBFOLDER = re.compile(r"^(logs|motion_search|native|db-[0-9a-f]{8,}\.npz\.derived)$")


def _files_outside(root: Path, cache: Path) -> list[str]:
    """Files and folders under ``root`` that are not top-level files of ``cache`` or files in one of its
    own subfolders (:data:`_CACHE_SUBFOLDER`)."""
    out = []
    if not root.is_dir():
        return out
    for dirpath, dirnames, filenames in os.walk(root):
        d = Path(dirpath)
        for name in filenames:
            p = d / name
            if p.parent == cache or (p.parent.parent == cache and _CACHE_SUBFOLDER.match(p.parent.name)):
                continue
            out.append(str(p.relative_to(root)))
        if d == cache:
            for name in dirnames:
                if not _CACHE_SUBFOLDER.match(name):
                    out.append(str((d / name).relative_to(root)) + "/")
    return sorted(out)


def main() -> int:
    results_path, cases_path, mem_cap, stop_above = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
    if mem_cap > 0:  # a hard cap so a runaway case fails with MemoryError instead of eating the machine
        resource.setrlimit(resource.RLIMIT_DATA, (mem_cap, mem_cap))
    cases = json.loads(Path(cases_path).read_text())
    sandbox = Path(os.environ["CORPUS_SANDBOX"]) if os.environ.get("CORPUS_SANDBOX") else None
    # the cache the commands use: CORPUS_CACHE where it is not LMM_STUDIO_CACHE (the no-home cases)
    cache_env = os.environ.get("CORPUS_CACHE") or os.environ.get("LMM_STUDIO_CACHE")
    cache = Path(cache_env) if cache_env else None
    seen = set(_files_outside(sandbox, cache)) if sandbox else set()
    with open(results_path, "a", encoding="utf-8") as results:
        def emit(obj):
            results.write(json.dumps(obj) + "\n")
            results.flush()

        for case in cases:
            emit({"start": case["id"]})
            # every case shows its own warnings, as a fresh process would (default filters, so no
            # ResourceWarning; the per-module "shown once" registries are invalidated)
            getattr(warnings, "_filters_mutated", lambda: None)()
            for d in case.get("mkdirs", []):
                Path(d).mkdir(parents=True, exist_ok=True)
            capture = {}
            saved = {}
            sys.stdout.flush()
            sys.stderr.flush()
            for fd in (1, 2):
                capture[fd] = tempfile.TemporaryFile()
                saved[fd] = os.dup(fd)
                os.dup2(capture[fd].fileno(), fd)
            rc, extra, uncaught = None, {}, None
            watched = None
            if case.get("watch") or case.get("watch_files"):   # what must be left as it was: a folder's
                watched = _fingerprints(case)                   # every file, the case's own files
            hooks = {}
            if case.get("before"):   # the state the case reads (tests/corpus/state_cases.py)
                from state_cases import before
                try:
                    hooks["setup_problems"] = before(case["before"], cache)
                except Exception as e:  # noqa: BLE001 - a broken setup fails the case, not the driver
                    hooks["setup_problems"] = [f"setup failed: {type(e).__name__}: {e}"]
            restore = _no_passwd() if case.get("no_passwd") else None
            t0 = time.perf_counter()
            try:
                rc, extra = _call(case)
            except MemoryError as e:
                uncaught = {"type": "MemoryError", "message": str(e)[:300], "trace": traceback.format_exc()[-3000:],
                            "memory_cap": True}
            except BaseException as e:  # noqa: BLE001 - whatever escapes is the finding
                uncaught = {"type": type(e).__name__, "message": str(e)[:300], "trace": traceback.format_exc()[-3000:]}
            seconds = time.perf_counter() - t0
            if restore is not None:
                restore()
            try:
                sys.stdout.flush()
                sys.stderr.flush()
            except Exception:  # noqa: BLE001
                pass
            out = {}
            for fd in (1, 2):
                os.dup2(saved[fd], fd)
                os.close(saved[fd])
                f = capture[fd]
                f.seek(0)
                out[fd] = f.read(OUTPUT_LIMIT).decode("utf-8", errors="replace")
                f.close()
            if watched is not None:
                now_seen = _fingerprints(case)
                extra["changed"] = sorted(k for k in set(watched) | set(now_seen) if watched.get(k) != now_seen.get(k))
            if case.get("after"):    # the right output (tests/corpus/state_cases.py)
                from state_cases import after
                hooks["output_problems"] = after(case["after"], cache, out[1])
            maxrss = peak_rss_bytes()
            result = {"id": case["id"], "argv": case.get("argv") or case.get("path"), "rc": rc, "stdout": out[1], "stderr": out[2], "uncaught": uncaught,
                      "seconds": seconds, "maxrss": maxrss, **extra, **hooks}
            if case.get("names"):   # what the error must name, known only when the job was made
                result["names"] = case["names"]
            if sandbox:
                now = set(_files_outside(sandbox, cache))
                result["stray"] = sorted(now - seen)
                seen = now
            emit(result)
            if maxrss > stop_above:
                return 3
    return 0


def _fingerprints(case: dict) -> dict:
    from special_cases import fingerprint, fingerprint_of

    out = fingerprint(Path(case["watch"])) if case.get("watch") else {}
    out.update({p: fingerprint_of(p) for p in case.get("watch_files", [])})
    return out


def _no_passwd():
    """Make this uid one without a passwd entry (as in some containers) until the returned call."""
    import pwd

    real = pwd.getpwuid

    def missing(uid):
        raise KeyError(f"getpwuid(): uid not found: {uid}")

    pwd.getpwuid = missing
    return lambda: setattr(pwd, "getpwuid", real)


def peak_rss_bytes() -> int:
    """This process's own resident high-water mark: ``VmHWM`` of /proc/self/status. Not ``ru_maxrss``:
    Linux carries that across fork and exec, so a driver started by a large pytest process would report
    the parent's memory (1.2 GB in a full suite run) before doing anything."""
    try:
        with open("/proc/self/status", "rb") as f:
            for line in f:
                if line.startswith(b"VmHWM:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


if __name__ == "__main__":
    sys.exit(main())

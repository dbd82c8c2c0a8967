"""Run corpus cases in driver subprocesses, never hanging: each case has a hard wall-clock limit, after
which the driver's whole process group is killed with SIGKILL and the remaining cases go on in a fresh
driver. Peak memory is each driver's own high-water mark (``ru_maxrss``, read by the driver after every
case and by :func:`os.wait4` for the whole process), under a hard ``RLIMIT_DATA`` cap so a runaway fails
with MemoryError instead of taking the machine's memory.
"""
from __future__ import annotations

import json
import os
import signal
import sys
import tempfile
import threading
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from pathlib import Path

DRIVER = Path(__file__).resolve().parent / "driver.py"
CASE_LIMIT_S = 30.0            # the bound per case
MEMORY_LIMIT_BYTES = 1 << 30   # the bound per case (peak resident memory)
MEMORY_CAP_BYTES = 3 << 30     # hard RLIMIT_DATA in the driver: a runaway stops here
POLL_S = 0.05


@dataclass
class Job:
    name: str
    cases: list[dict]
    env: dict = field(default_factory=dict)   # added to the environment; a None value unsets the name


def _read_lines(path: Path, offset: int) -> tuple[list[dict], int]:
    try:
        with open(path, "rb") as f:
            f.seek(offset)
            data = f.read()
    except FileNotFoundError:
        return [], offset
    end = data.rfind(b"\n") + 1
    lines = [json.loads(x) for x in data[:end].splitlines() if x.strip()]
    return lines, offset + end


def _kill_group(pgid: int) -> None:
    try:
        os.killpg(pgid, signal.SIGKILL)
    except (ProcessLookupError, PermissionError):
        pass


def _one_driver(job: Job, cases: list[dict], workdir: Path, attempt: int, python: str,
                case_limit_s: float) -> tuple[dict, list[dict]]:
    """Run ``cases`` in one driver until it ends; -> (results by id, the cases not started)."""
    import subprocess

    stem = f"{job.name}-{attempt}"
    cases_file = workdir / f"{stem}.cases.json"
    results_file = workdir / f"{stem}.results.jsonl"
    log_file = workdir / f"{stem}.log"
    cases_file.write_text(json.dumps(cases))
    env = {k: v for k, v in {**os.environ, **job.env}.items() if v is not None}   # None: unset
    with open(log_file, "wb") as log:
        proc = subprocess.Popen([python, str(DRIVER), str(results_file), str(cases_file), str(MEMORY_CAP_BYTES),
                                 str(MEMORY_LIMIT_BYTES)], stdin=subprocess.DEVNULL, stdout=log, stderr=log,
                                env=env, start_new_session=True)
    results: dict = {}
    offset = 0
    current, started_at = None, None
    status = rusage = None
    killed_for = None
    try:
        while True:
            pid, st, ru = os.wait4(proc.pid, os.WNOHANG)
            lines, offset = _read_lines(results_file, offset)
            for line in lines:
                if "start" in line:
                    current, started_at = line["start"], time.monotonic()
                else:
                    results[line["id"]] = line
                    current = started_at = None
            if pid:
                status, rusage = st, ru
                proc.returncode = os.waitstatus_to_exitcode(st)
                break
            if current is not None and time.monotonic() - started_at > case_limit_s:
                killed_for = current
                _kill_group(proc.pid)
                _, st, ru = os.wait4(proc.pid, 0)
                status, rusage = st, ru
                proc.returncode = os.waitstatus_to_exitcode(st)
                lines, offset = _read_lines(results_file, offset)
                for line in lines:
                    if "id" in line:
                        results[line["id"]] = line
                break
            time.sleep(POLL_S)
    finally:
        if proc.returncode is None:  # interrupted (e.g. Ctrl+C in pytest): leave nothing running
            _kill_group(proc.pid)
            os.wait4(proc.pid, 0)
        _kill_group(proc.pid)  # anything the driver started and left behind
    process_maxrss = rusage.ru_maxrss * 1024 if rusage is not None else None
    log_tail = log_file.read_bytes()[-2000:].decode("utf-8", errors="replace") if log_file.exists() else ""
    if current is not None and current not in results:
        if killed_for == current:
            results[current] = {"id": current, "timeout": True, "seconds": case_limit_s,
                                "maxrss": process_maxrss}
        else:
            code = proc.returncode
            why = f"killed by signal {-code}" if code is not None and code < 0 else f"exit status {code}"
            results[current] = {"id": current, "died": why, "maxrss": process_maxrss, "driver_log": log_tail}
    for r in results.values():
        r.setdefault("process_maxrss", process_maxrss)
    done = set(results)
    not_started = [c for c in cases if c["id"] not in done]
    if not_started and current is None and not results:
        # the driver died before starting anything (import error...): report instead of looping
        for c in not_started:
            results[c["id"]] = {"id": c["id"], "died": f"driver failed to start (status {proc.returncode})",
                                "driver_log": log_tail}
        not_started = []
    return results, not_started


def run_job(job: Job, workdir: Path, python: str = sys.executable, case_limit_s: float = CASE_LIMIT_S) -> dict:
    remaining = list(job.cases)
    results: dict = {}
    attempt = 0
    t0 = time.monotonic()
    while remaining:
        got, remaining = _one_driver(job, remaining, workdir, attempt, python, case_limit_s)
        results.update(got)
        attempt += 1
    for r in results.values():
        r["job"] = job.name
    results_meta = {"job": job.name, "seconds": time.monotonic() - t0, "drivers": attempt}
    return {"results": results, "meta": results_meta}


def run_jobs(jobs: list[Job], workers: int = 2, python: str = sys.executable,
             case_limit_s: float = CASE_LIMIT_S) -> tuple[dict, list[dict]]:
    """Run every job (``workers`` at a time) -> (results by case id, per-job timing)."""
    workdir = Path(tempfile.mkdtemp(prefix="corpus-harness-"))
    results, metas = {}, []
    lock = threading.Lock()

    def work(job):
        out = run_job(job, workdir, python, case_limit_s)
        with lock:
            results.update(out["results"])
            metas.append(out["meta"])

    try:
        with ThreadPoolExecutor(max_workers=workers) as pool:
            for f in [pool.submit(work, j) for j in jobs]:
                f.result()
    finally:
        import shutil
        shutil.rmtree(workdir, ignore_errors=True)
    return results, metas

"""The bad-input corpus (tests/corpus/, see its README.md) against every command that reads each kind.

Each case is one file (or argument, output target, or prepared state: tests/corpus/state_cases.py) x one
command, run in a driver subprocess (tests/corpus/driver.py; cheap cases grouped per command,
runaway-prone ones and studio starts alone) with a hard 30 s limit and a memory cap. A rejected case must: exit 1 (2 for bad arguments), print exactly one non-empty
stderr line that names the file (and the field, where the table gives one), print no traceback, never
echo a referenced file's contents, write nothing outside its place, and stay under 30 s and 1 GiB of
peak resident memory. Valid control files must work (exit 0), so a broken harness cannot pass; a usable
state must give the right output (the state cases' ``after`` checks).
"""
from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent / "corpus"))
import corpus_cases as cc  # noqa: E402
from corpus_harness import CASE_LIMIT_S, MEMORY_LIMIT_BYTES, run_jobs  # noqa: E402

CASES = cc.case_table()
BY_ID = {c.id: c for c in CASES}


@pytest.fixture(scope="module")
def corpus(request, tmp_path_factory):
    """Runs the selected cases (all, or what -k kept) once, in parallel drivers."""
    selected = {item.callspec.params["case_id"] for item in request.session.items
                if item.originalname == "test_corpus_case" and hasattr(item, "callspec")}
    tmp = tmp_path_factory.mktemp("corpus")
    targets, mounts = cc.make_targets(tmp)
    try:
        jobs, skipped = cc.build_jobs([c for c in CASES if c.id in selected], tmp, targets)
        results, _ = run_jobs(jobs, workers=2)
        yield {"results": results, "skipped": skipped, "targets": targets, "tmp": tmp}
    finally:
        cc.unmount(mounts)


def _lines(text: str) -> list[str]:
    return [line for line in text.splitlines() if line.strip()]


def _head(text: str, n: int = 4) -> str:
    lines = _lines(text)
    return " | ".join(lines[:n]) + (f" | ... ({len(lines)} lines)" if len(lines) > n else "")


def problems(case: cc.Case, r: dict, targets: dict | None = None) -> list[str]:
    """What is wrong with a case's result (empty: it passed)."""
    out = []
    if r.get("names"):   # known only when the job was made (a display's number)
        case = dataclasses.replace(case, names=tuple(r["names"]))
    if r.get("timeout"):
        return [f"still running after {CASE_LIMIT_S:g} s: killed"]
    if r.get("died"):
        return [f"the driver died ({r['died']}): {_head(r.get('driver_log', ''))}"]
    if r.get("uncaught"):
        u = r["uncaught"]
        where = [ln.strip() for ln in u.get("trace", "").splitlines() if ln.strip().startswith("File ")][-1:]
        cap = " (the harness's memory cap)" if u.get("memory_cap") else ""
        out.append(f"traceback: {u['type']}: {u['message'][:200]}{cap} at {where[0] if where else '?'}")
    stderr = r.get("stderr", "")
    lines = _lines(stderr)
    if "Traceback" in stderr:
        out.append("'Traceback' in stderr")
    if cc.SECRET_LINE in stderr or cc.SECRET_LINE in r.get("stdout", ""):
        out.append("echoed the contents of a file it was pointed at")
    if r.get("seconds", 0) > CASE_LIMIT_S:
        out.append(f"took {r['seconds']:.1f} s (> {CASE_LIMIT_S:g} s)")
    if r.get("maxrss") and r["maxrss"] > MEMORY_LIMIT_BYTES:
        out.append(f"peak resident memory {r['maxrss'] / 2**20:.0f} MiB (> {MEMORY_LIMIT_BYTES / 2**20:.0f} MiB)")
    if r.get("changed"):
        out.append(f"changed or left files it was given: {', '.join(r['changed'][:4])}")
    if r.get("stray"):
        out.append(f"wrote outside its place: {', '.join(r['stray'][:4])}")
    out += [f"setup: {p}" for p in r.get("setup_problems") or []]
    out += [f"output: {p}" for p in r.get("output_problems") or []]
    rc = r.get("rc")
    if case.expect == "note":   # usable input that goes wrong at run time: exit 0 and one note line
        if rc != 0 or len(lines) != 1 or not lines[0].startswith(case.names[0]):
            out.append(f"expected exit 0 and one '{case.names[0]}' line: exit {rc}; stderr: {_head(stderr)}")
        elif case.field and case.field not in lines[0]:
            out.append(f"the note does not say {case.field!r}: {_head(stderr)}")
        return out
    if case.expect == "accept":
        if rc != 0:
            out.append(f"a valid file was refused: exit {rc}; stderr: {_head(stderr)}")
        elif case.kind == "state" and any(not ln.startswith(("note: ", "warning: ")) for ln in lines):
            # usable state: the command works as if it were intact, at most saying what it computed again
            out.append(f"exit 0, but stderr has more than notes and warnings: {_head(stderr)}")
        return out
    if case.expect == "layout":
        if rc == 1:
            out += _one_line_naming(case, lines, stderr)
        elif rc == 0:
            out += _layout_in_range(r.get("layout") or {})
        elif not r.get("uncaught"):
            out.append(f"exit {rc}")
        return out
    if r.get("uncaught"):
        return out
    if case.expect == "usage":
        if rc != 2:
            out.append(f"exit {rc}, expected 2 (usage error); stderr: {_head(stderr)}")
        if not lines or "error" not in lines[-1].lower() or case.names[0] not in lines[-1]:
            out.append(f"last stderr line does not say error and name {case.names[0]}: {_head(stderr)}")
        extra = [ln for ln in lines[:-1] if not (ln.startswith("usage:") or ln.startswith(" "))]
        if extra:
            out.append(f"stderr has more than argparse's usage and one error line: {_head(stderr)}")
        return out
    if rc != 1:
        what = "accepted (exit 0)" if rc == 0 else f"exit {rc}, expected 1"
        out.append(f"{what}; stderr: {_head(stderr) or '(empty)'}")
        if rc == 0:
            return out
    out += _one_line_naming(case, lines, stderr)
    return out


def _one_line_naming(case, lines, stderr) -> list[str]:
    out = []
    if len(lines) != 1:
        out.append(f"stderr has {len(lines)} non-empty lines, expected 1: {_head(stderr)}")
    text = "\n".join(lines)
    if not any(n in text for n in case.names):
        out.append(f"the error does not name {' or '.join(case.names)}: {_head(stderr) or '(empty)'}")
    for word in (case.field,) if isinstance(case.field, str) else case.field or ():   # one word or several
        if word.lower() not in text.lower():
            out.append(f"the error does not name the field {word!r}: {_head(stderr) or '(empty)'}")
    return out


def _layout_in_range(layout: dict) -> list[str]:
    """An accepted layout must hold window rectangles a window and a framebuffer can have."""
    out = []
    if not layout.get("numbers_are_ints", False):
        out.append("accepted, with non-integer positions or sizes")
    vw, vh = layout.get("reference_size", [0, 0])
    if not all(isinstance(v, int) and 1 <= v <= cc.LAYOUT_MAX for v in (vw, vh)):
        out.append(f"accepted, with Viewport={vw},{vh} outside 1..{cc.LAYOUT_MAX}")
    for key, rect in layout.get("windows", {}).items():
        pos, size = rect.get("pos"), rect.get("size")
        if size is not None and not all(isinstance(v, (int, float)) and math.isfinite(v) and 1 <= v <= cc.LAYOUT_MAX
                                        for v in size):
            out.append(f"accepted, with window {key} Size={size} outside 1..{cc.LAYOUT_MAX}")
        if pos is not None and not all(isinstance(v, (int, float)) and math.isfinite(v) and abs(v) <= cc.LAYOUT_MAX
                                       for v in pos):
            out.append(f"accepted, with window {key} Pos={pos} outside +-{cc.LAYOUT_MAX}")
    return out


def _recording_left_behind(case: cc.Case, targets: dict) -> list[str]:
    """A recording left on an unwritable or full target must load in our reader."""
    variant = case.id.split(":")[0].split("-", 1)[1]
    folder = targets.get(variant)
    if folder is None or not Path(folder).is_dir():
        return []
    from lmm.data import bvh

    out = []
    for p in sorted(Path(folder).glob("take*")):
        if p.suffix == ".bvh":
            try:
                anim = bvh.load(p)
                if anim.n_frames < 1:
                    out.append(f"left {p.name} with no frames")
            except Exception as e:  # noqa: BLE001
                out.append(f"left {p.name}, which does not load: {str(e)[:160]}")
    return out


@pytest.mark.parametrize("case_id", [c.id for c in CASES])
def test_corpus_case(corpus, case_id):
    case = BY_ID[case_id]
    if case_id in corpus["skipped"]:
        pytest.skip(corpus["skipped"][case_id])
    r = corpus["results"].get(case_id)
    assert r is not None, f"{case_id}: no result from the harness"
    found = problems(case, r)
    if case.recording:
        found += _recording_left_behind(case, corpus["targets"])
    argv = r.get("argv") or ""
    assert not found, (f"{case_id} ({case.what}) [{r.get('job')}, {r.get('seconds', 0):.2f} s, "
                       f"{(r.get('maxrss') or 0) / 2**20:.0f} MiB]: " + "; ".join(found) + (f" argv={argv}" if argv else ""))

"""Every command's output on success fits a terminal (24 lines) unless asked for more (``--verbose``,
``--json -``): the details go to the files the commands write."""
from __future__ import annotations

import importlib.util
import json
import re

import pytest

from app.cli import main

SCREEN_LINES = 24


def lines_of(capsys, *argv) -> list[str]:
    rc = main([str(a) for a in argv])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return (out.out + out.err).splitlines()


@pytest.fixture(scope="module")
def session_run(tmp_path_factory):
    """A 2 s motion matching run kept as a session and a BVH recording."""
    tmp = tmp_path_factory.mktemp("run")
    assert main(["run", "--input", "builtin:circle", "--seconds", "2", "--record", str(tmp / "run.bvh"),
                 "--session", str(tmp / "run.lmmsession"), "--quiet"]) == 0
    (tmp / "b.json").write_text('{"transition_cost": 0.3}')
    return tmp


def test_run_prints_the_main_metrics_and_verbose_prints_them_all(capsys):
    short = lines_of(capsys, "run", "--input", "builtin:circle", "--seconds", "1")
    assert len(short) <= SCREEN_LINES, "\n".join(short)
    assert any(line.startswith("foot_skating_cm_s ") for line in short)
    assert short[-1].startswith("(") and "more metrics: --verbose, or --metrics-json PATH" in short[-1]
    every = lines_of(capsys, "run", "--input", "builtin:circle", "--seconds", "1", "--verbose")
    more = int(short[-1].strip("(").split()[0])
    assert len(every) == len(short) - 1 + more and any(line.startswith("tag_share_walk ") for line in every)


def test_check_data_summarises_and_verbose_lists_every_finding(capsys):
    short = lines_of(capsys, "check-data")
    assert len(short) <= SCREEN_LINES, "\n".join(short)
    total = int(short[-1].split()[0])          # "53 findings in 6 takes, 0 inside used ranges"
    assert short[-1].endswith("inside used ranges") and total > SCREEN_LINES
    assert any(line.startswith("outside used ranges: ") for line in short)
    every = lines_of(capsys, "check-data", "--verbose")
    assert len([line for line in every if re.match(r"\S+: \w+ frames \d+-\d+ ", line)]) == total
    assert any(line.startswith("seconds by root speed") for line in every)


def test_build_db_prints_a_few_data_check_warnings_and_verbose_all_of_them(capsys):
    from app.commands.build_db import LISTED_WARNINGS

    used = int(lines_of(capsys, "check-data", "--quiet")[-1].split(", ")[1].split()[0])
    findings = lambda lines: [line for line in lines if re.match(r"warning: \S+: \w+ frames \d+-\d+ ", line)]  # noqa: E731
    short = lines_of(capsys, "build-db")
    assert len(findings(short)) == min(used, LISTED_WARNINGS)
    assert any(f"warning: {used - LISTED_WARNINGS} more data-check findings" in line for line in short) == (
        used > LISTED_WARNINGS)
    assert len(findings(lines_of(capsys, "build-db", "--verbose"))) == used


def test_bench_prints_the_headline_figures_and_verbose_prints_them_all(capsys, tmp_path):
    from app.commands.cpp_reference import compiler

    short = lines_of(capsys, "bench", "--queries", "20", "--frame-ticks", "60", "--frame-rounds", "1",
                     "--json", tmp_path / "bench.json")
    assert len(short) <= SCREEN_LINES, "\n".join(short)
    res = json.loads((tmp_path / "bench.json").read_text())
    assert f"({sum(map(len, res.values()))} figures in all: --verbose prints them, --json PATH writes them)" in short
    text = "\n".join(short)
    s, f, m = res["search"], res["frame"], res["memory"]
    assert f"runtime call p50 / p90 / p99: {s['runtime_call_p50_us']:.4g} / {s['runtime_call_p90_us']:.4g} / " \
           f"{s['runtime_call_p99_us']:.4g} us" in text
    assert f"brute force {s['bruteforce_us']:.4g} us, accelerated {s['accelerated_us']:.4g} us" in text
    assert f"[memory] MM {m['mm_bytes'] / 1e6:.2f} MB, LMM {m['lmm_bytes'] / 1e6:.2f} MB" in text
    if compiler():      # whole frames and networks, ours / C++ = ratio
        assert (f"MM  median {f['mm_frame_us']:.4g} / {f['cpp_mm_frame_us']:.4g} us = "
                f"{f['mm_frame_over_cpp']:.4g}x") in text
        assert f"stepper      {f['lmm_network_stepper_us']:.4g} / {f['lmm_network_stepper_cpp_us']:.4g} us" in text
    every = lines_of(capsys, "bench", "--sections", "memory", "--verbose")
    assert every[0] == "[memory]" and [line.split()[0] for line in every[1:]] == list(m)


@pytest.mark.parametrize("argv", [
    ["build-db"],
    ["coverage", "--json", "{tmp}/coverage.json"],
    ["compare", "{run}/run.bvh", "{run}/run.bvh"],
    ["input-from", "{run}/run.bvh", "--out", "{tmp}/input.csv"],
    ["replay", "{run}/run.lmmsession"],
    ["ab", "{run}/run.lmmsession", "--tuning", "{run}/b.json", "--from-tick", "60"],
    ["trace", "{run}/run.lmmsession", "--out", "{tmp}/trace.csv"],
    ["physics", "{run}/run.bvh"],
], ids=lambda argv: argv[0])
def test_the_other_commands_fit_a_terminal(capsys, session_run, tmp_path, argv):
    if argv[0] == "physics" and importlib.util.find_spec("mujoco") is None:
        pytest.skip("physics needs mujoco (the physics extra)")
    lines = lines_of(capsys, *(a.format(tmp=tmp_path, run=session_run) for a in argv))
    assert 0 < len(lines) <= SCREEN_LINES, "\n".join(lines)

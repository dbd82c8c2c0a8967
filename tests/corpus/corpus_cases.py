"""The corpus: every bad file (committed under tests/corpus/<kind>/, or generated at test time) and the
commands that read its kind, plus bad command-line arguments and unwritable output targets.

A case is one file x one command. ``build(tmp)`` generates the big files into ``tmp`` and returns the
harness jobs (cheap cases grouped per command in one driver process; runaway-prone cases each in their
own process) and the case table used by ``tests/test_corpus.py`` and ``bench/corpus_report.py``.
"""
from __future__ import annotations

import gzip
import json
import os
import shutil
import subprocess
import zipfile
import dataclasses
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from corpus_harness import Job
import session_files
import special_cases
import state_cases

CORPUS = Path(__file__).resolve().parent
ROOT = CORPUS.parents[1]
WEIGHTS = ROOT / "lmm" / "data" / "weights" / "default.npz"
COMPRESSOR = WEIGHTS.with_name("compressor.npz")
SECRET_LINE = "SECRET-FIRST-LINE-do-not-echo-7f3a"  # first line of manifest/secret.txt: never echoed

KIND_COMMANDS = {
    "bvh": ("reader", "view", "build-db", "check-data", "run"),
    "manifest": ("build-db", "check-data", "run", "eval"),
    "input": ("run",),
    "preset": ("run",),
    "weights": ("run", "eval", "export-onnx"),
    "layout": ("loader",),
    "session": ("replay",),
    "motion": ("view", "build-db", "check-data"),     # glTF and FBX files (in a manifest for the last two)
}


@dataclass
class Spec:
    what: str
    field: str | None = None          # a word the error line must hold besides the file's name
    names: tuple = ()                 # file names accepted as "naming the file" (default: the case file's)
    commands: tuple | None = None     # default: every command of the kind
    solo: bool = False                # its own process (runaway-prone), memory and time measured alone
    generated: bool = False           # made by generate() into the temporary folder


# ---- the table: relative path under tests/corpus (or the generated folder) -> Spec -----------------
FILES: dict[str, Spec] = {
    # BVH (issue items first)
    "bvh/frame_time_1000.bvh": Spec("Frame Time: 1000 (ZeroDivisionError in database.py)", "Frame Time"),
    "bvh/frame_time_1e-300.bvh": Spec("Frame Time: 1e-300 (built a 2-frame database)", "Frame Time"),
    "bvh/value_1e308.bvh": Spec("a position of 1e308 (run: cannot reshape array of size 0)"),
    "bvh/gzip_bomb_1gib.bvh.gz": Spec("1 MB .bvh.gz inflating to 1 GiB of trailing spaces (8.4 GB)",
                                      commands=("reader", "view", "build-db"), solo=True, generated=True),
    "bvh/frame_time_nan.bvh": Spec("Frame Time: nan", "Frame Time"),
    "bvh/frame_time_inf.bvh": Spec("Frame Time: inf", "Frame Time"),
    "bvh/value_minus_1e308_rotation.bvh": Spec("a rotation of -1e308 degrees"),
    "bvh/value_1e30.bvh": Spec("a root position of 1e30 cm"),
    "bvh/offset_1e308.bvh": Spec("an OFFSET of 1e308", "OFFSET"),
    "bvh/channel_count_huge.bvh": Spec("CHANNELS 99999999 with 3 names", "CHANNELS"),
    "bvh/two_frames.bvh": Spec("a valid 2-frame take: below the database's 4-frame minimum",
                               commands=("build-db", "check-data", "run")),
    "bvh/no_toe_joint.bvh": Spec("the manifest's left_toe bone (LeftToe) is not in the file", "LeftToe",
                                 names=("no_toe_joint.bvh", "corpus-bvh.json"),
                                 commands=("build-db", "check-data", "run")),
    "bvh/joints_20000.bvh": Spec("a chain of 20,000 nested joints (joint count / nesting limit)",
                                 commands=("reader", "build-db"), solo=True, generated=True),
    "bvh/gzip_in_gzip.bvh.gz": Spec("a gzip inside a gzip (reported as 'binary data (NUL byte)')", "gzip"),
    "bvh/offsets_all_zero.bvh": Spec("every OFFSET 0 (built, then run: ZeroDivisionError in ik.py)", "OFFSET",
                                     commands=("build-db", "run")),
    # manifests
    # glTF and FBX (issue 37)
    "motion/truncated.glb": Spec("a glb cut short", "truncated"),
    "motion/no_animation.glb": Spec("a glb with a skin and no animation", "no animation"),
    "motion/not_gltf.gltf": Spec("JSON that is not glTF", "not a glTF 2.0 file"),
    "motion/no_skin.gltf": Spec("a glTF without a skin", "no skin"),
    "motion/garbage.fbx": Spec("bytes that are not FBX", "not a readable FBX file"),
    "motion/no_skeleton.fbx": Spec("an FBX mesh without bones", "no skeleton"),
    "manifest/name_traversal.json": Spec("name '/../../../../x' wrote the cache outside its folder", "name"),
    "manifest/name_subdir.json": Spec("name 'sub/dir/name' created folders in the cache", "name"),
    "manifest/name_300_chars.json": Spec("a 300-character name", "name"),
    "manifest/name_nul.json": Spec("a name holding NUL", "name"),
    "manifest/simulation_order_-1.json": Spec("simulation.order: -1", "order"),
    "manifest/speed_scale_1e-9.json": Spec("speed_scale: 1e-9", "speed_scale"),
    "manifest/target_fps_1e12.json": Spec("target_fps: 1e12 (asks numpy for TiB)", "target_fps",
                                          commands=("build-db", "run"), solo=True),
    "manifest/target_fps_1e5.json": Spec("target_fps: 1e5 (67 s, 5.5 GB, 957 MB cache)", "target_fps",
                                         commands=("build-db", "run"), solo=True),
    "manifest/median_window_1000001.json": Spec("contacts.median_window: 1000001 (70 s, 3.9 GB)",
                                                "median_window", commands=("build-db",), solo=True),
    "manifest/clips_10000.json": Spec("10,000 clip entries (still running after 90 s)", "clips",
                                      commands=("build-db",), solo=True, generated=True),
    "manifest/nested_100000.json": Spec("nested 100,000 deep (RecursionError)", generated=True),
    "manifest/not_utf8.json": Spec("bytes 0xff 0xfe in the name (not UTF-8)"),
    "manifest/number_5000_digits.json": Spec("target_fps with 5,000 digits"),
    "manifest/target_fps_0.001.json": Spec("target_fps: 0.001", "target_fps"),
    "manifest/simulation_position_window_1000001.json": Spec("simulation.position_window: 1000001",
                                                             "position_window"),
    "manifest/unit_scale_1e300.json": Spec("unit_scale: 1e300", "unit_scale"),
    "manifest/range_huge.json": Spec("a range [0, 1e15]", "range"),
    "manifest/range_reversed.json": Spec("a range [100, 10]", "range"),
    "manifest/clip_is_text_file.json": Spec("a clip naming a text file (its first line must not be echoed)",
                                            names=("clip_is_text_file.json", "secret.txt")),
    "manifest/clip_is_folder.json": Spec("a clip naming a folder", names=("clip_is_folder.json", "manifest")),
    "manifest/clip_missing.json": Spec("a clip naming a missing file",
                                       names=("clip_missing.json", "no_such_take.bvh")),
    "manifest/hips_forward_zero.json": Spec("hips_forward_axis [0, 0, 0]", "hips_forward_axis"),
    "manifest/trajectory_offsets_huge.json": Spec("a trajectory offset of 1e9 frames", "offsets"),
    "manifest/bvh_frame_time_1000.json": Spec("a clip with Frame Time: 1000",
                                              names=("bvh_frame_time_1000.json", "frame_time_1000.bvh")),
    "manifest/bvh_value_1e308.json": Spec("a clip with a value of 1e308",
                                          names=("bvh_value_1e308.json", "value_1e308.bvh")),
    "manifest/empty_object.json": Spec("{} (no clips)", "clips"),
    "manifest/top_level_list.json": Spec("a JSON list instead of an object"),
    # input logs
    "input/time_1e308.csv": Spec("a row at time 1e308 (OverflowError)", "time"),
    "input/time_1e12.csv": Spec("a row at time 1e12 s (longer than any run)", "time"),
    "input/time_inf.csv": Spec("a row at time inf", "time"),
    "input/time_negative_first.csv": Spec("a first row at time -1e308", "time"),
    "input/camera_azimuth_1e308.csv": Spec("camera_azimuth 1e308", "camera_azimuth"),
    "input/header_only.csv": Spec("a header and no rows"),
    "input/empty.csv": Spec("an empty file"),
    "input/not_utf8.csv": Spec("bytes 0xff 0xfe in a row"),
    "input/nul_bytes.csv": Spec("a NUL byte in a row"),
    "input/duplicate_column.csv": Spec("left_x twice in the header", "left_x"),
    "input/cr_only_1.1m_rows.csv": Spec("1.1 M rows ended by CR alone (got past the \\n-counting line limit: "
                                        "14 s, 1.77 GB)", "lines", solo=True, generated=True),
    "input/u2028_1.1m_rows.csv": Spec("1.1 M rows ended by U+2028 (1.57 GB)", "lines", solo=True, generated=True),
    # tuning presets
    "preset/not_utf8.json": Spec("not UTF-8 (UnicodeDecodeError)"),
    "preset/nested_100000.json": Spec("nested 100,000 deep (RecursionError)", generated=True),
    "preset/number_5000_digits.json": Spec("a 5,000-digit number (int limit ValueError)"),
    "preset/unknown_feature_channel.json": Spec("feature_weights names an unknown channel (accepted silently)",
                                                "no_such_channel"),
    "preset/empty_feature_weights.json": Spec("an empty feature_weights (accepted silently)", "feature_weights"),
    "preset/value_1e308.json": Spec("stick_deadzone: 1e308", "stick_deadzone"),
    "preset/value_nan.json": Spec("stick_deadzone: NaN", "stick_deadzone"),
    "preset/value_infinity.json": Spec("inertialization_halflife_s: Infinity", "inertialization_halflife_s"),
    "preset/top_level_list.json": Spec("a JSON list instead of an object"),
    "preset/unknown_field.json": Spec("an unknown field", "no_such_field"),
    "preset/feature_weight_1e308.json": Spec("a feature weight of 1e308", "left_foot_position"),
    # nesting is refused by a scan before parsing, so the line names the depth, not the field
    "preset/nested_200.json": Spec("tag_bias nested 200 deep", "nested"),
    "preset/tag_excluded_string.json": Spec("a tag exclusion given as \"yes\"", "tag_excluded.fall"),
    "preset/tag_excluded_list.json": Spec("tag_excluded as a list of tags", "tag_excluded"),
    "preset/tag_bias_string.json": Spec("a tag bias given as a string", "tag_bias.fall"),
    "preset/empty.json": Spec("an empty file"),
    "preset/big_64mib.json": Spec("64 MiB of whitespace around {} (size limit before reading)",
                                  solo=True, generated=True),
    # weights (all generated from the shipped default.npz with one thing changed)
    "weights/meta_missing_n_bones.npz": Spec("metadata without n_bones (KeyError 'n_bones')", "n_bones",
                                             generated=True),
    "weights/meta_n_bones_abc.npz": Spec("metadata n_bones: 'abc' (int('abc'))", "n_bones", generated=True),
    "weights/meta_is_list.npz": Spec("metadata is a JSON list (AttributeError)", "metadata", generated=True),
    "weights/meta_hidden_missing.npz": Spec("networks.decompressor without hidden sizes", "hidden",
                                            generated=True),
    "weights/meta_not_json.npz": Spec("metadata bytes are not JSON", "metadata", generated=True),
    "weights/feature_inv_scale_zero.npz": Spec("feature_inv_scale all 0 (181 cm/s foot sliding)",
                                               "feature_inv_scale", generated=True),
    "weights/out_std_zero.npz": Spec("decompressor.out_std all 0", "out_std", generated=True),
    "weights/weights_3e38.npz": Spec("decompressor.W0 all 3e38 (cannot reshape array of size 0)",
                                     generated=True),
    "weights/object_member.npz": Spec("an extra member that is a pickled object array", generated=True),
    "weights/not_a_zip.npz": Spec("a text file named .npz", generated=True),
    "weights/extra_1gib_member.npz": Spec("an extra 1 GiB array (deflated to ~1 MB; cost 1.2 GB)",
                                          solo=True, generated=True),
    # studio layout files (loader: refuse with the file named, or clamp into range)
    "layout/pos_inf.ini": Spec("Pos=inf,22 (OverflowError in layouts.py)", "Pos"),
    "layout/pos_nan.ini": Spec("Pos=nan,nan", "Pos"),
    "layout/viewport_inf.ini": Spec("Viewport=inf,900 (OverflowError)", "Viewport"),
    "layout/viewport_0_0.ini": Spec("Viewport=0,0 (framebuffer incomplete)", "Viewport"),
    "layout/viewport_negative.ini": Spec("Viewport=-1600,-900", "Viewport"),
    "layout/size_huge.ini": Spec("Size=1e8,1e8 (framebuffer incomplete)", "Size"),
    "layout/size_1e308.ini": Spec("Size=1e308,1e308", "Size"),
    "layout/size_zero.ini": Spec("Size=0,0", "Size"),
    "layout/size_negative.ini": Spec("Size=-500,-500", "Size"),
    "layout/pos_huge.ini": Spec("Pos=1e15,1e15", "Pos"),
    "layout/table_columns_2e9.ini": Spec("[Table] with 2e9 columns (segfault inside ImGui)", "Table"),
    "layout/table_columns_1e8.ini": Spec("[Table] with 1e8 columns (3.3 GB, then saved a negative count)", "Table"),
    "layout/table_columns_negative.ini": Spec("[Table][0xD4BD52E9,-7936], as the studio saved it (every later "
                                              "start crashed or hung in ImGui's ini writer)", "Table"),
    "layout/table_column_index_huge.ini": Spec("Column 99999 of a 13-column table", "Column"),
    "layout/table_width_negative.ini": Spec("a column Width=-5", "Width"),
    "layout/table_refscale_nan.ini": Spec("RefScale=nan", "RefScale"),
    "layout/unknown_section.ini": Spec("a section the studio never writes", "section"),
    "layout/window_unknown_key.ini": Spec("a window key the studio never writes", "Zoom"),
    "layout/docking_size_huge.ini": Spec("a dock space of 2e9 pixels", "Size"),
    # session files (issue 33), each made from a valid 2 s session (tests/corpus/session_files.py)
    **{f"session/{name}": Spec(what, word, generated=True) for name, (what, word) in session_files.BAD.items()},
}
GOOD_SESSION = "session/good.lmmsession"   # generated too: the control of the session kind

# the older corpora each of whose files is broken in one way: run them through every command too
EXTERNAL = {"bvh": (ROOT / "tests" / "bvh_corpus", ("*.bvh", "*.bvh.gz")),
            "input": (ROOT / "tests" / "input_corpus", ("*.csv",))}
EXTERNAL_VALID = {"valid_crlf.csv"}

# layouts accepted after clamping must hold numbers in these ranges (what a window/framebuffer can be)
LAYOUT_MAX = 32768

# bad command-line arguments: (id, argv, the argument the error names)
ARG_CASES = [
    ("run-seconds-inf", ["run", "--input", "builtin:circle", "--seconds", "inf", "--quiet"], "--seconds"),
    ("run-seconds-1e308", ["run", "--input", "builtin:circle", "--seconds", "1e308", "--quiet"], "--seconds"),
    ("run-seconds-nan", ["run", "--input", "builtin:circle", "--seconds", "nan", "--quiet"], "--seconds"),
    ("run-seconds-negative", ["run", "--input", "builtin:circle", "--seconds", "-1", "--quiet"], "--seconds"),
    ("run-fps-inf", ["run", "--input", "builtin:circle", "--seconds", "1", "--fps", "inf", "--quiet"], "--fps"),
    ("run-fps-zero", ["run", "--input", "builtin:circle", "--seconds", "1", "--fps", "0", "--quiet"], "--fps"),
    ("run-fps-nan", ["run", "--input", "builtin:circle", "--seconds", "1", "--fps", "nan", "--quiet"], "--fps"),
    ("run-fps-1e308", ["run", "--input", "builtin:circle", "--seconds", "1", "--fps", "1e308", "--quiet"], "--fps"),
    ("run-fps-1e-300", ["run", "--input", "builtin:circle", "--seconds", "1", "--fps", "1e-300", "--quiet"],
     "--fps"),
    ("eval-seconds-inf", ["eval", "--seconds", "inf", "--queries", "64"], "--seconds"),
    ("eval-queries-negative", ["eval", "--seconds", "1", "--queries", "-1"], "--queries"),
    ("eval-queries-1e12", ["eval", "--seconds", "1", "--queries", "1000000000000"], "--queries"),
    ("view-size-huge", ["view", "{good}/walk.bvh", "--screenshot", "{out}/huge.png", "--width", "100000",
                        "--height", "100000"], "--width"),
    ("view-frame-huge", ["view", "{good}/walk.bvh", "--screenshot", "{out}/frame.png", "--frame",
                         "1" + "0" * 30], "--frame"),
    ("view-frame-negative", ["view", "{good}/walk.bvh", "--screenshot", "{out}/neg.png", "--frame", "-1"], "--frame"),
    ("studio-height-1e11", ["studio", "--height", "99999999999", "--frames", "1"], "--height"),
    ("studio-render-scale-nan", ["studio", "--render-scale", "nan", "--frames", "1"], "--render-scale"),
    ("studio-render-scale-0", ["studio", "--render-scale", "0", "--frames", "1"], "--render-scale"),
    ("studio-render-scale-negative", ["studio", "--render-scale", "-1", "--frames", "1"], "--render-scale"),
    ("studio-render-scale-inf", ["studio", "--render-scale", "inf", "--frames", "1"], "--render-scale"),
    ("studio-samples-1000", ["studio", "--samples", "1000", "--frames", "1"], "--samples"),
    ("train-frames-1", ["train", "stepper", "--frames", "1", "--out", "{out}/train"], "--frames"),
    ("view-samples-1000", ["view", "{good}/walk.bvh", "--screenshot", "{out}/samples.png", "--samples", "1000"],
     "--samples"),
]

# unwritable output targets: (id, argv with {T} the target folder, the target file name)
TARGET_CASES = [
    ("run-metrics-json", ["run", "--input", "builtin:circle", "--seconds", "1", "--quiet", "--metrics-json",
                          "{T}/metrics.json"], "metrics.json"),
    ("run-record", ["run", "--input", "builtin:circle", "--seconds", "10", "--quiet", "--record", "{T}/take.bvh"],
     "take"),
    ("build-db-out", ["build-db", "--manifest", "{good}/manifest.json", "--quiet", "--no-checks", "--out",
                      "{T}/db.npz"], "db.npz"),
    ("view-screenshot", ["view", "{good}/walk.bvh", "--screenshot", "{T}/shot.png"], "shot.png"),
    ("export-onnx-out", ["export-onnx", "--out", "{T}/onnx"], "onnx"),
    ("check-data-json", ["check-data", "--manifest", "{good}/manifest.json", "--quiet", "--json", "{T}/c.json"],
     "c.json"),
]


@dataclass
class Case:
    id: str
    kind: str                 # bvh, manifest, input, preset, weights, layout, args, target, control
    command: str
    file: str                 # what is tested (relative path, argument case or target)
    what: str
    expect: str               # "reject" (exit 1), "usage" (exit 2), "accept" (exit 0), "layout"
    names: tuple = ()         # one of these must be in the error line
    field: str | tuple | None = None   # a word the error line must hold (a tuple: every one of them)
    solo: bool = False
    call: dict = dataclasses.field(default_factory=dict)   # what the driver runs
    recording: str | None = None               # a recording that, if left behind, must load


def _argv(kind: str, command: str, path: str, tmp: Path, cid: str) -> dict:
    out = tmp / "out"
    if command == "reader":
        return {"call": "reader", "path": path}
    if command == "loader":
        return {"call": "layout", "path": path}
    if kind in ("bvh", "motion") and command != "view":
        manifest = tmp / "wrapped" / (Path(path).name + ".corpus-bvh.json")
        manifest.parent.mkdir(parents=True, exist_ok=True)
        m = json.loads((CORPUS / "good" / "manifest.json").read_text())
        m["name"] = "corpus-bvh"
        m["clips"] = [{"file": path}]
        manifest.write_text(json.dumps(m))
        path = str(manifest)
    manifest_cmds = {
        "build-db": ["build-db", "--manifest", path],
        "check-data": ["check-data", "--manifest", path, "--quiet"],
        "run": ["run", "--manifest", path, "--input", "builtin:circle", "--seconds", "1", "--quiet"],
        "eval": ["eval", "--manifest", path, "--seconds", "1", "--queries", "64"],
    }
    if command == "view":
        argv = ["view", path, "--screenshot", str(out / f"{_safe(cid)}.png")]
    elif kind in ("bvh", "manifest", "motion"):
        argv = manifest_cmds[command]
    elif kind == "input":
        argv = ["run", "--input", path, "--quiet"]  # no --seconds: the log's own length
    elif kind == "session":
        argv = ["replay", path, "--quiet"]
    elif kind == "preset":
        argv = ["run", "--input", "builtin:circle", "--seconds", "1", "--tuning", path, "--quiet"]
    elif kind == "weights":
        argv = {"run": ["run", "--controller", "lmm", "--weights", path, "--input", "builtin:circle",
                        "--seconds", "1", "--quiet"],
                "eval": ["eval", "--weights", path, "--compressor", str(COMPRESSOR), "--seconds", "1",
                         "--queries", "64"],
                "export-onnx": ["export-onnx", "--weights", path, "--out", str(out / _safe(cid))]}[command]
    else:
        raise ValueError(kind)
    return {"call": "cli", "argv": argv}


def _watched(call: dict, path: Path) -> list[str]:
    """The files a file case must leave as they were: the case's file, and the manifest wrapping it."""
    out = [str(path)]
    argv = call.get("argv", [])
    if "--manifest" in argv and argv[argv.index("--manifest") + 1] != str(path):
        out.append(argv[argv.index("--manifest") + 1])
    return out


def _safe(s: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in s)


def case_table() -> list[Case]:
    """Every case, without generating anything (ids are stable for pytest's parametrisation)."""
    cases = []
    for rel, spec in FILES.items():
        kind = rel.split("/")[0]
        for command in spec.commands or KIND_COMMANDS[kind]:
            cases.append(Case(f"{command}:{rel}", kind, command, rel, spec.what,
                              "layout" if kind == "layout" else "reject",
                              spec.names or (Path(rel).name,), spec.field, spec.solo))
    for kind, (folder, patterns) in EXTERNAL.items():
        files = sorted({p for pat in patterns for p in folder.glob(pat)} - {folder / n for n in EXTERNAL_VALID})
        for p in files:
            rel = f"{folder.name}/{p.name}"
            for command in KIND_COMMANDS[kind]:
                cases.append(Case(f"{command}:{rel}", kind, command, rel, f"from {folder.name}/README.md",
                                  "reject", (p.name,)))
    for cid, argv, arg in ARG_CASES:
        cases.append(Case(f"args:{cid}", "args", argv[0], " ".join(argv[1:]), "bad argument", "usage", (arg,)))
    for variant in ("notdir", "readonly", "full", "nearlyfull"):
        for cid, argv, name in TARGET_CASES:
            if variant == "nearlyfull" and cid != "run-record":
                continue  # 48 KiB left: the recording's header fits, its frames do not
            folder = "a_regular_file" if variant == "notdir" else f"targets/{variant}"
            cases.append(Case(f"target-{variant}:{cid}", "target", argv[0], f"{variant}/{name}",
                              f"unwritable target ({variant})", "reject", (name, folder),
                              recording=name if cid == "run-record" else None))
    for table, what in ((special_cases.COLLISIONS, "an output that would destroy an input, another output or "
                                                   "a special file"),
                        (special_cases.SPECIAL_INPUTS, "a special file or a non-ASCII number as input")):
        for cid, argv, word in table:
            cases.append(Case(f"special:{cid}", "special", argv[0], cid, what, "reject", (word,)))
    for cid, argv, word in special_cases.NOTES:
        cases.append(Case(f"special:{cid}", "special", argv[0], cid, "weights whose networks give NaN or runaway "
                          "poses: run on, one note naming the tick, none of them recorded", "note", (word,)))
    for cid, command, _, expect, what, _, _ in state_cases.derived_cases():
        note = expect == "note"
        cases.append(Case(f"state:{cid}", "state", command, cid, what, expect, ("note: ",) if note else (),
                          "damaged cached array" if note else None))
    for cid, command, _, expect, what, _, _ in state_cases.db_cache_cases():
        cases.append(Case(f"state:{cid}", "state", command, cid, what, expect, ("note: ",), "building"))
    for cid, command, _, what, _ in state_cases.no_home_cases():
        cases.append(Case(f"state:{cid}", "state", command, cid, what, "accept"))
    for cid, _, _, expect, names, field, what, _ in state_cases.display_cases():  # solo: a job each
        cases.append(Case(f"state:{cid}", "state", "studio", cid, what, expect, names, field))
    controls = [("bvh", "good/walk.bvh"), ("manifest", "good/manifest.json"), ("input", "good/input.csv"),
                ("preset", "good/preset.json"), ("weights", "shipped/default.npz"), ("layout", "good/layout.ini"),
                ("session", GOOD_SESSION)]
    for kind, rel in controls:
        for command in KIND_COMMANDS[kind]:
            if command == "eval":
                # manifest: the shipped networks are for the shipped data, so eval refuses them, rightly;
                # weights: a valid eval of the shipped data costs ~25 s and ~1 GiB, too much for a control
                continue
            cases.append(Case(f"control-{command}:{rel}", "control", command, rel, "a valid file: must work",
                              "accept" if kind != "layout" else "layout", (Path(rel).name,), call={"kind": kind}))
    return cases


# ---- generated files ---------------------------------------------------------------------------------

def _bomb(path: Path, size: int = 1 << 30) -> None:
    """A valid small take followed by ``size`` bytes of spaces, gzip-compressed (~1 MB on disk)."""
    text = (CORPUS / "good" / "walk.bvh").read_bytes()
    chunk = b" " * (1 << 22)
    with gzip.open(path, "wb", compresslevel=9) as f:
        f.write(text.rstrip(b"\n"))
        for _ in range(size // len(chunk)):
            f.write(chunk)
        f.write(b"\n")


def _deep_joints(path: Path, n: int = 20000) -> None:
    lines = ["HIERARCHY", "ROOT J0", "{", "OFFSET 0 0 0",
             "CHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation"]
    for i in range(1, n):
        lines += [f"JOINT J{i}", "{", "OFFSET 0 1 0", "CHANNELS 3 Zrotation Xrotation Yrotation"]
    lines += ["End Site", "{", "OFFSET 0 1 0", "}"] + ["}"] * n
    values = " ".join(["0"] * (6 + 3 * (n - 1)))
    lines += ["MOTION", "Frames: 2", "Frame Time: 0.033333", values, values]
    path.write_text("\n".join(lines) + "\n")


def _weights(path: Path, change) -> None:
    with np.load(WEIGHTS, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    meta = json.loads(arrays["metadata"].tobytes())
    meta_bytes = change(arrays, meta)
    if meta_bytes is None:
        meta_bytes = json.dumps(meta).encode()
    arrays["metadata"] = np.frombuffer(meta_bytes, dtype=np.uint8)
    np.savez(path, **arrays)


def _extra_member(path: Path, size: int = 1 << 30) -> None:
    """The shipped weights plus a deflated 1 GiB float32 zero array, streamed (never held in memory)."""
    shutil.copyfile(WEIGHTS, path)
    n = size // 4
    header = np.lib.format.header_data_from_array_1_0(np.zeros(0, np.float32))
    header["shape"] = (n,)
    with zipfile.ZipFile(path, "a", compression=zipfile.ZIP_DEFLATED, compresslevel=1) as z:
        with z.open("extra.npy", "w", force_zip64=True) as f:
            np.lib.format.write_array_header_1_0(f, header)
            chunk = bytes(1 << 22)
            for _ in range(size // len(chunk)):
                f.write(chunk)


def _set(arrays, meta, path_keys, value):
    d = meta
    for k in path_keys[:-1]:
        d = d[k]
    if value is KeyError:
        del d[path_keys[-1]]
    else:
        d[path_keys[-1]] = value


def generate(gen: Path, only: set | None = None) -> None:
    """Write the generated files under ``gen`` (``only``: relative paths wanted; default all)."""
    def want(rel):
        return (only is None or rel in only) and not (gen / rel).exists()

    for sub in ("bvh", "manifest", "preset", "weights"):
        (gen / sub).mkdir(parents=True, exist_ok=True)
    if want("bvh/gzip_bomb_1gib.bvh.gz"):
        _bomb(gen / "bvh/gzip_bomb_1gib.bvh.gz")
    if want("bvh/joints_20000.bvh"):
        _deep_joints(gen / "bvh/joints_20000.bvh")
    if want("manifest/clips_10000.json"):
        m = json.loads((CORPUS / "good" / "manifest.json").read_text())
        m["clips"] = [{"file": str(CORPUS / "good" / "walk.bvh")}] * 10000
        (gen / "manifest/clips_10000.json").write_text(json.dumps(m))
    if want("manifest/nested_100000.json"):
        (gen / "manifest/nested_100000.json").write_text('{"clips": ' + "[" * 100000 + "]" * 100000 + "}")
    if want("preset/nested_100000.json"):
        (gen / "preset/nested_100000.json").write_text('{"tag_bias": ' + "[" * 100000 + "]" * 100000 + "}")
    for rel, sep in (("input/cr_only_1.1m_rows.csv", "\r"), ("input/u2028_1.1m_rows.csv", "\u2028")):
        if want(rel):
            (gen / "input").mkdir(parents=True, exist_ok=True)
            with open(gen / rel, "w", encoding="utf-8", newline="") as f:
                f.write("time,left_x,left_y,right_x,right_y,walk,strafe" + sep)
                f.write(("0,0,0,0,0,0,0" + sep) * 1_100_000)
    if want("preset/big_64mib.json"):
        with open(gen / "preset/big_64mib.json", "wb") as f:
            f.write(b"{")
            chunk = b" " * (1 << 20)
            for _ in range(64):
                f.write(chunk)
            f.write(b"}\n")
    w = gen / "weights"
    changes = {
        "meta_missing_n_bones.npz": lambda a, m: _set(a, m, ["n_bones"], KeyError),
        "meta_n_bones_abc.npz": lambda a, m: _set(a, m, ["n_bones"], "abc"),
        "meta_is_list.npz": lambda a, m: json.dumps([1, 2, 3]).encode(),
        "meta_hidden_missing.npz": lambda a, m: _set(a, m, ["networks", "decompressor", "hidden"], KeyError),
        "meta_not_json.npz": lambda a, m: b"\x80not json{",
        "feature_inv_scale_zero.npz": lambda a, m: _set(a, m, ["feature_inv_scale"],
                                                        [0.0] * len(m["feature_inv_scale"])),
        "out_std_zero.npz": lambda a, m: a.__setitem__("decompressor.out_std",
                                                       np.zeros_like(a["decompressor.out_std"])),
        "weights_3e38.npz": lambda a, m: a.__setitem__("decompressor.W0",
                                                       np.full_like(a["decompressor.W0"], 3e38)),
    }
    for name, change in changes.items():
        if want(f"weights/{name}"):
            _weights(w / name, change)
    if want("weights/object_member.npz"):
        with np.load(WEIGHTS, allow_pickle=False) as z:
            arrays = {k: z[k] for k in z.files}
        arrays["evil"] = np.array([{"a": 1}, None], dtype=object)
        np.savez(w / "object_member.npz", **arrays)
    if want("weights/not_a_zip.npz"):
        (w / "not_a_zip.npz").write_text("this is not a zip file\n")
    if want("weights/extra_1gib_member.npz"):
        _extra_member(w / "extra_1gib_member.npz")
    sessions = {rel.split("/", 1)[1] for rel in FILES if rel.startswith("session/") and want(rel)}
    if sessions or want(GOOD_SESSION):
        good = gen / GOOD_SESSION
        if not good.exists():
            session_files.make_good(good)
        session_files.make_bad(good, gen / "session", only=sessions)


def case_path(case: Case, gen: Path) -> Path:
    if case.kind == "control" and case.file.startswith("shipped/"):
        return WEIGHTS
    if case.file == GOOD_SESSION:
        return gen / GOOD_SESSION
    spec = FILES.get(case.file)
    if spec is not None and spec.generated:
        return gen / case.file
    for folder, _ in EXTERNAL.values():
        if case.file.startswith(folder.name + "/"):
            return folder / Path(case.file).name
    return CORPUS / case.file


# ---- unwritable targets -----------------------------------------------------------------------------

def make_targets(tmp: Path) -> tuple[dict, list]:
    """{variant: folder or None} and the mount points to unmount (and display servers to stop, see
    :func:`unmount`). notdir: a folder path under a regular file (always). readonly: a read-only tmpfs;
    full: a full tmpfs; nearlyfull: one with 48 KiB left (these need mount: root; not root, readonly is a
    chmod 555 folder). ``displays``: {variant: DISPLAY or None} (state_cases.start_displays)."""
    targets = {"notdir": None, "readonly": None, "full": None, "nearlyfull": None}
    plain = tmp / "targets" / "a_regular_file"
    plain.parent.mkdir(parents=True, exist_ok=True)
    plain.write_text("not a folder\n")
    targets["notdir"] = plain / "sub"
    mounts = []
    if hasattr(os, "geteuid") and os.geteuid() == 0 and shutil.which("mount"):
        ro = tmp / "targets" / "readonly"
        full = tmp / "targets" / "full"
        nearly = tmp / "targets" / "nearlyfull"
        for d, opts in ((ro, "size=256k,ro"), (full, "size=256k"), (nearly, "size=512k")):
            d.mkdir(parents=True, exist_ok=True)
            r = subprocess.run(["mount", "-t", "tmpfs", "-o", opts, "tmpfs", str(d)], capture_output=True)
            if r.returncode == 0:
                mounts.append(d)
        if ro in mounts:
            targets["readonly"] = ro
        for d, left, variant in ((full, 0, "full"), (nearly, 48 * 1024, "nearlyfull")):
            if d in mounts:
                st = os.statvfs(d)
                try:
                    with open(d / "filler", "wb") as f:
                        f.write(b"\0" * max(st.f_bavail * st.f_frsize - left, 0))
                        if not left:
                            while True:  # to the last byte
                                f.write(b"\0" * 4096)
                                f.flush()
                except OSError:
                    pass
                targets[variant] = d
    elif hasattr(os, "geteuid"):  # not root: a read-only folder is enough
        ro = tmp / "targets" / "readonly"
        ro.mkdir(parents=True, exist_ok=True)
        ro.chmod(0o555)
        targets["readonly"] = ro
    # the displays a studio cannot open its window on (state_cases.display_cases): Xvfb servers
    targets["displays"], servers = state_cases.start_displays()
    return targets, mounts + servers


def unmount(mounts: list) -> None:
    """Unmount the target folders and stop the display servers :func:`make_targets` started."""
    for d in mounts:
        if isinstance(d, subprocess.Popen):
            d.terminate()
            d.wait(timeout=10)
        else:
            subprocess.run(["umount", "-l", str(d)], capture_output=True)


# ---- jobs -----------------------------------------------------------------------------------------------

def build_jobs(cases: list[Case], tmp: Path, targets: dict) -> tuple[list[Job], dict]:
    """Driver jobs for ``cases`` (generating what they need) -> (jobs, {case id: skip reason})."""
    gen = tmp / "generated"
    needed = {c.file for c in cases if (c.file in FILES and FILES[c.file].generated) or c.file == GOOD_SESSION}
    if any(c.kind == "special" and c.file in special_cases.NEEDS_SESSION for c in cases):
        needed.add(GOOD_SESSION)
    generate(gen, needed)
    (tmp / "out").mkdir(parents=True, exist_ok=True)
    good = CORPUS / "good"
    skipped = {}
    grouped: dict[str, list[dict]] = {}
    solo: list[tuple[str, dict, bool]] = []
    group_env: dict[str, dict] = {}   # a group's own environment (state cases)

    def env_for(name, sandboxed):
        env = {"LMM_STUDIO_CONFIG": str(tmp / "config"), "PYTHONPATH": str(ROOT), "PYTHONDONTWRITEBYTECODE": "1"}
        if sandboxed:  # a private cache 6 folders deep, so a path escaping it still lands in the sandbox
            sandbox = tmp / "sandbox" / name
            cache = sandbox / "a" / "b" / "c" / "d" / "e" / "f" / "cache"
            cache.mkdir(parents=True, exist_ok=True)
            env.update({"CORPUS_SANDBOX": str(sandbox), "LMM_STUDIO_CACHE": str(cache)})
        return {**env, **group_env.get(name, {})}

    for c in cases:
        if c.kind == "state":
            got = _state_entry(c, tmp, targets, env_for, group_env)
            if isinstance(got, str):
                skipped[c.id] = got
                continue
            call, group = got
        elif c.kind == "args":
            argv = [a.format(good=good, out=tmp / "out") for a in dict((i, v) for i, v, _ in ARG_CASES)[
                c.id.split(":", 1)[1]]]
            call = {"call": "cli", "argv": argv}
            group = f"args-{c.command}"
        elif c.kind == "target":
            variant = c.id.split(":")[0].split("-", 1)[1]
            folder = targets.get(variant)
            if folder is None:
                skipped[c.id] = f"no {variant} target on this machine (needs root and mount)"
                continue
            argv = dict((i, v) for i, v, _ in TARGET_CASES)[c.id.split(":", 1)[1]]
            call = {"call": "cli", "argv": [a.format(T=folder, good=good) for a in argv]}
            group = f"target-{variant}"
        elif c.kind == "special":   # its own folder of copies, checked unchanged by the driver
            folder = tmp / "special" / _safe(c.file)
            special_cases.prepare(folder, c.file)
            if c.file in special_cases.NEEDS_SESSION:
                shutil.copyfile(gen / GOOD_SESSION, folder / "s.lmmsession")
            argv = dict((i, v) for i, v, _ in special_cases.COLLISIONS + special_cases.SPECIAL_INPUTS
                        + special_cases.NOTES)[c.file]
            call = {"call": "cli", "argv": [a.format(T=folder, good=good) for a in argv], "watch": str(folder)}
            group = f"special-{c.command}"
        elif c.kind == "control":
            kind = c.call["kind"]
            call = _argv(kind, c.command, str(case_path(c, gen)), tmp, c.id)
            call["watch_files"] = _watched(call, case_path(c, gen))
            group = f"control-{kind}"
        else:
            call = _argv(c.kind, c.command, str(case_path(c, gen)), tmp, c.id)
            call["watch_files"] = _watched(call, case_path(c, gen))
            group = f"{c.kind}-{c.command}"
        entry = {"id": c.id, **call}
        sandboxed = c.kind in ("bvh", "manifest") or (c.kind == "control" and c.call.get("kind") in ("bvh", "manifest"))
        if c.solo:
            solo.append((f"solo-{_safe(c.id)}", entry, sandboxed))
        else:
            grouped.setdefault(group, []).append(entry)
    jobs = []
    for name, entry, sandboxed in solo:  # the slow ones first, so they overlap the cheap groups
        jobs.append(Job(name, [entry], env_for(name, sandboxed)))
    for name, entries in grouped.items():
        sandboxed = (name.split("-")[0] in ("bvh", "manifest", "state")
                     or name in ("control-bvh", "control-manifest"))
        jobs.append(Job(name, entries, env_for(name, sandboxed)))
    return jobs, skipped


def _fill(obj, **values):
    """``obj`` (strings, lists, dicts of them) with ``{NAME}`` replaced by ``values``."""
    if isinstance(obj, str):
        return obj.format(**values)
    if isinstance(obj, list):
        return [_fill(x, **values) for x in obj]
    if isinstance(obj, dict):
        return {k: _fill(v, **values) for k, v in obj.items()}
    return obj


def _state_entry(c: Case, tmp: Path, targets: dict, env_for, group_env: dict):
    """A state case's driver entry and job group (preparing the group's state once), or why it is skipped."""
    derived = {row[0]: row for row in state_cases.derived_cases() + state_cases.db_cache_cases()}
    no_home = {row[0]: row for row in state_cases.no_home_cases()}
    display = {row[0]: row for row in state_cases.display_cases()}
    if c.file in derived:
        _, command, argv, _, _, damage, after = derived[c.file]
        group = f"state-{c.file.split('-')[0]}-{command}"   # state-derived-run, state-db-run, ...
        T, O = tmp / "state" / group / "in", tmp / "state" / group / "out"
        if not T.exists():
            cache = Path(env_for(group, True)["LMM_STUDIO_CACHE"])
            state_cases.prepare_derived(T, O, cache)
        return {"call": "cli", "argv": _fill(argv, T=T, O=O), "watch": str(T), "before": damage,
                "after": _fill(after, O=O)}, group
    if c.file in no_home:
        _, _, argv, _, after = no_home[c.file]
        group = "state-no-home"
        sandbox = tmp / "sandbox" / group
        tmpdir = sandbox / "tmp"
        tmpdir.mkdir(parents=True, exist_ok=True)
        home = state_cases.no_home_dir(tmpdir)
        group_env[group] = {**{k: None for k in state_cases.NO_HOME_UNSET}, "TMPDIR": str(tmpdir),
                            "CORPUS_CACHE": str(home / ".cache" / "lmm-studio")}
        return {"call": "cli", "argv": argv, "watch": str(CORPUS / "good"), "no_passwd": True,
                "after": _fill(after, H=home)}, group
    _, variant, argv, _, names, _, _, solo = display[c.file]
    shown = (targets.get("displays") or {}).get(variant)
    if shown is None:
        return f"no {variant} display on this machine (needs Xvfb, or a free display number from :77)"
    group = f"state-display-{variant}" + (f"-{_safe(c.file)}" if solo else "")
    config = tmp / "sandbox" / group / "config"   # inside the sandbox: a file the studio writes there is stray
    after = {}
    saved = state_cases.SAVED_LAYOUTS.get(c.file)
    if saved is not None:   # the user's saved layout: moved aside (outside the sandbox, checked by after)
        config = tmp / "state" / f"{group}-config"
        config.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(saved, config / "layout.ini")
        after = {"same": [[str(config / "layout.ini.bad"), str(saved)]]}
    group_env[group] = {**state_cases.display_env(variant, shown), "LMM_STUDIO_CONFIG": str(config)}
    F = tmp / "state" / group
    if not F.exists():
        state_cases.prepare_display_case(F, c.file)
    if c.file in state_cases.SHARED_CACHE:
        group_env[group].update(CORPUS_SANDBOX=None, LMM_STUDIO_CACHE=os.environ.get("LMM_STUDIO_CACHE"))
    extra = {}
    if c.file == "studio-no-home":   # the no-home environment (as state-no-home) on a working display
        tmpdir = tmp / "sandbox" / group / "tmp"
        tmpdir.mkdir(parents=True, exist_ok=True)
        home = state_cases.no_home_dir(tmpdir)
        group_env[group].update({k: None for k in state_cases.NO_HOME_UNSET}, TMPDIR=str(tmpdir),
                                CORPUS_CACHE=str(home / ".cache" / "lmm-studio"))
        extra = {"no_passwd": True}
        after = {"exists": [str(home / ".cache" / "lmm-studio" / "db-*.npz")]}
    generated = tmp / "generated"
    if "{gen}" in " ".join(argv):
        generate(generated, {a.split("{gen}/", 1)[1] for a in argv if "{gen}" in a})
    return {"call": "cli", "argv": _fill(argv, F=F, gen=generated), "watch": str(F), "after": after, **extra,
            "names": [n.format(display=repr(shown)) for n in names]}, group

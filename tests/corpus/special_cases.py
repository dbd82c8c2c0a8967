"""Issue 36's corpus cases: outputs that would destroy an input, another output or a special file;
special files (FIFOs, devices, loops of links) given as inputs; numbers that are not ASCII.

Each case runs in its own folder ``{T}`` holding fresh copies of the good files and the special files
made by :func:`prepare` (a FIFO, a link to ``/dev/null``, a hard link of the input log, a loop of links,
manifests pointing at them). The driver hashes every file of ``{T}`` before and after the case (a
regular file by content, a FIFO or link by kind and target): a case that changes one fails, whatever
it printed. Every case must be refused with exit 1 and one line naming the file.
"""
from __future__ import annotations

import json
import os
import shutil
from pathlib import Path

CORPUS = Path(__file__).resolve().parent
GOOD = CORPUS / "good"
WEIGHTS = CORPUS.parents[1] / "lmm" / "data" / "weights" / "default.npz"

_RUN = ["run", "--input", "builtin:circle", "--seconds", "1", "--quiet"]

# (id, argv ({T}: the case's folder, {good}: tests/corpus/good), a word the error line must hold)
COLLISIONS = [
    ("run-record-input-is-record", _RUN + ["--record", "{T}/x.bvh", "--record-input", "{T}/x.bvh"], "x.bvh"),
    ("run-metrics-is-record", _RUN + ["--record", "{T}/x.bvh", "--metrics-json", "{T}/x.bvh"], "x.bvh"),
    ("run-record-is-input", ["run", "--input", "{T}/input.csv", "--quiet", "--record", "{T}/input.csv"],
     "input.csv"),
    ("run-record-beside-its-input-log", ["run", "--input", "{T}/take.input.csv", "--record", "{T}/take.bvh",
                                         "--seconds", "2", "--quiet"], "take.input.csv"),
    ("run-record-is-weights", ["run", "--controller", "lmm", "--weights", "{T}/w.npz", "--input",
                               "builtin:circle", "--seconds", "1", "--quiet", "--record", "{T}/w.npz"], "w.npz"),
    ("run-metrics-is-tuning", _RUN + ["--tuning", "{T}/preset.json", "--metrics-json", "{T}/preset.json"],
     "preset.json"),
    ("run-metrics-is-a-hard-link-of-the-input", ["run", "--input", "{T}/input.csv", "--quiet", "--metrics-json",
                                                 "{T}/hard.csv"], "hard.csv"),
    ("run-record-is-a-link-to-dev-null", _RUN + ["--record", "{T}/null"], "null"),
    ("run-metrics-is-a-link-to-dev-null", _RUN + ["--metrics-json", "{T}/null"], "null"),
    ("run-metrics-is-a-fifo", _RUN + ["--metrics-json", "{T}/fifo"], "fifo"),
    ("run-record-is-a-take-of-the-manifest", _RUN + ["--manifest", "{T}/manifest.json", "--record", "{T}/walk.bvh"],
     "walk.bvh"),
    ("run-metrics-is-the-manifest", _RUN + ["--manifest", "{T}/manifest.json", "--metrics-json",
                                            "{T}/manifest.json"], "manifest.json"),
    ("run-session-is-the-tuning", _RUN + ["--tuning", "{T}/preset.json", "--session", "{T}/preset.json"],
     "preset.json"),
    ("build-db-out-is-the-manifest", ["build-db", "--manifest", "{T}/manifest.json", "--out", "{T}/manifest.json",
                                      "--quiet", "--no-checks"], "manifest.json"),
    ("build-db-out-is-a-take", ["build-db", "--manifest", "{T}/manifest.json", "--out", "{T}/walk.bvh", "--quiet",
                                "--no-checks"], "walk.bvh"),
    ("build-db-out-is-dev-null", ["build-db", "--manifest", "{T}/manifest.json", "--out", "{T}/null", "--quiet",
                                  "--no-checks"], "null"),
    ("train-out-holds-a-fifo", ["train", "decompressor", "--manifest", "{T}/manifest.json", "--out", "{T}/trainout",
                                "--iterations", "1", "--quiet"], "fifo"),
    ("export-onnx-out-is-the-weights", ["export-onnx", "--weights", "{T}/decompressor.onnx", "--out", "{T}"],
     "decompressor.onnx"),
    ("eval-json-is-the-weights", ["eval", "--weights", "{T}/w.npz", "--compressor", str(WEIGHTS.with_name(
        "compressor.npz")), "--json", "{T}/w.npz", "--seconds", "1", "--queries", "64"], "w.npz"),
    ("view-screenshot-is-the-file", ["view", "{T}/walk.bvh", "--screenshot", "{T}/walk.bvh"], "walk.bvh"),
    ("bench-json-is-a-link-to-dev-null", ["bench", "--sections", "memory", "--json", "{T}/null"], "null"),
    ("bench-json-is-the-manifest", ["bench", "--sections", "memory", "--manifest", "{T}/manifest.json", "--json",
                                    "{T}/manifest.json"], "manifest.json"),
    ("coverage-json-is-the-manifest", ["coverage", "--manifest", "{T}/manifest.json", "--json", "{T}/manifest.json"],
     "manifest.json"),
    ("coverage-png-is-a-take", ["coverage", "--manifest", "{T}/manifest.json", "--png", "{T}/walk.bvh"], "walk.bvh"),
    ("check-data-json-is-a-take", ["check-data", "--manifest", "{T}/manifest.json", "--quiet", "--json",
                                   "{T}/walk.bvh"], "walk.bvh"),
    ("check-data-png-is-the-manifest", ["check-data", "--manifest", "{T}/manifest.json", "--quiet", "--png",
                                        "{T}/manifest.json"], "manifest.json"),
    ("compare-json-is-a-motion", ["compare", "{T}/walk.bvh", "{T}/walk.bvh", "--json", "{T}/walk.bvh"], "walk.bvh"),
    ("input-from-out-is-the-take", ["input-from", "{T}/walk.bvh", "--manifest", "{T}/manifest.json", "--out",
                                    "{T}/walk.bvh"], "walk.bvh"),
    ("input-from-json-is-out", ["input-from", "{T}/walk.bvh", "--manifest", "{T}/manifest.json", "--out",
                                "{T}/o.csv", "--json", "{T}/o.csv"], "o.csv"),
    ("physics-json-is-the-file", ["physics", "{T}/walk.bvh", "--json", "{T}/walk.bvh"], "walk.bvh"),
    ("find-json-is-the-query", ["find", "{T}/walk.bvh", "--frames", "0:30", "--in", "{T}/manifest.json", "--json",
                                "{T}/walk.bvh", "--quiet"], "walk.bvh"),
    # every other output argument: an input, another output, a link to /dev/null or a FIFO
    ("run-record-input-is-the-tuning", _RUN + ["--tuning", "{T}/preset.json", "--record-input", "{T}/preset.json"],
     "preset.json"),
    ("run-session-is-the-record", _RUN + ["--record", "{T}/x.bvh", "--session", "{T}/x.bvh"], "x.bvh"),
    ("run-metrics-is-the-events", _RUN + ["--events", "{T}/preset.json", "--metrics-json", "{T}/preset.json"],
     "preset.json"),
    ("run-record-input-is-a-link-to-dev-null", _RUN + ["--record-input", "{T}/null"], "null"),
    ("run-session-is-a-link-to-dev-null", _RUN + ["--session", "{T}/null"], "null"),
    ("run-session-is-a-fifo", _RUN + ["--session", "{T}/fifo"], "fifo"),
    ("run-record-is-a-fifo", _RUN + ["--record", "{T}/fifo"], "fifo"),
    ("build-db-out-is-a-fifo", ["build-db", "--manifest", "{T}/manifest.json", "--out", "{T}/fifo", "--quiet",
                                "--no-checks"], "fifo"),
    ("train-json-is-the-manifest", ["train", "decompressor", "--manifest", "{T}/manifest.json", "--out", "{T}.out/w",
                                    "--json", "{T}/manifest.json", "--iterations", "1", "--quiet"], "manifest.json"),
    ("train-json-is-a-link-to-dev-null", ["train", "decompressor", "--manifest", "{T}/manifest.json", "--out",
                                          "{T}.out/w", "--json", "{T}/null", "--iterations", "1", "--quiet"], "null"),
    ("train-out-is-a-link-to-dev-null", ["train", "decompressor", "--manifest", "{T}/manifest.json", "--out",
                                         "{T}/null", "--iterations", "1", "--quiet"], "null"),
    ("eval-json-is-the-input", ["eval", "--input", "{T}/input.csv", "--json", "{T}/input.csv", "--seconds", "1",
                                "--queries", "64"], "input.csv"),
    ("eval-json-is-the-compressor", ["eval", "--weights", "{T}/w.npz", "--compressor", "{T}/compressor.npz", "--json",
                                     "{T}/compressor.npz", "--seconds", "1", "--queries", "64"], "compressor.npz"),
    ("eval-json-is-a-link-to-dev-null", ["eval", "--weights", "{T}/w.npz", "--json", "{T}/null", "--seconds", "1",
                                         "--queries", "64"], "null"),
    ("eval-plots-is-the-weights", ["eval", "--weights", "{T}/w.npz", "--plots", "{T}/w.npz", "--seconds", "1",
                                   "--queries", "64"], "w.npz"),
    ("export-onnx-out-is-a-link-to-dev-null", ["export-onnx", "--weights", "{T}/w.npz", "--out", "{T}/null"], "null"),
    ("view-screenshot-is-a-link-to-dev-null", ["view", "{T}/walk.bvh", "--screenshot", "{T}/null"], "null"),
    ("view-video-is-a-fifo", ["view", "{T}/walk.bvh", "--video", "{T}/fifo"], "fifo"),
    ("coverage-json-is-a-link-to-dev-null", ["coverage", "--manifest", "{T}/manifest.json", "--json", "{T}/null"],
     "null"),
    ("coverage-png-is-a-fifo", ["coverage", "--manifest", "{T}/manifest.json", "--png", "{T}/fifo"], "fifo"),
    ("check-data-json-is-a-link-to-dev-null", ["check-data", "--manifest", "{T}/manifest.json", "--quiet", "--json",
                                               "{T}/null"], "null"),
    ("check-data-png-is-a-fifo", ["check-data", "--manifest", "{T}/manifest.json", "--quiet", "--png", "{T}/fifo"],
     "fifo"),
    ("input-from-out-is-a-link-to-dev-null", ["input-from", "{T}/walk.bvh", "--manifest", "{T}/manifest.json",
                                              "--out", "{T}/null"], "null"),
    ("physics-json-is-a-fifo", ["physics", "{T}/walk.bvh", "--json", "{T}/fifo"], "fifo"),
    ("compare-json-is-a-link-to-dev-null", ["compare", "{T}/walk.bvh", "{T}/walk.bvh", "--json", "{T}/null"], "null"),
    ("find-json-is-a-fifo", ["find", "{T}/walk.bvh", "--frames", "0:30", "--in", "{T}/manifest.json", "--json",
                             "{T}/fifo", "--quiet"], "fifo"),
    ("replay-record-is-the-session", ["replay", "{T}/s.lmmsession", "--record", "{T}/s.lmmsession", "--quiet"],
     "s.lmmsession"),
    ("replay-metrics-is-a-link-to-dev-null", ["replay", "{T}/s.lmmsession", "--metrics-json", "{T}/null", "--quiet"],
     "null"),
    ("ab-json-is-the-tuning", ["ab", "{T}/s.lmmsession", "--tuning", "{T}/preset.json", "--json", "{T}/preset.json",
                               "--quiet"], "preset.json"),
    ("export-gltf-out-is-the-file", ["export-gltf", "{T}/walk.bvh", "--out", "{T}/walk.bvh"], "walk.bvh"),
    ("build-db-out-is-a-hard-link-of-the-take", ["build-db", "--manifest", "{T}/manifest.json", "--out",
                                                 "{T}/hard.bvh", "--quiet", "--no-checks"], "hard.bvh"),
    ("train-json-is-a-take", ["train", "decompressor", "--manifest", "{T}/manifest.json", "--out", "{T}.out/w",
                              "--json", "{T}/walk.bvh", "--iterations", "1", "--quiet"], "walk.bvh"),
    ("eval-json-is-the-manifest", ["eval", "--manifest", "{T}/manifest.json", "--json", "{T}/manifest.json",
                                   "--seconds", "1", "--queries", "64"], "manifest.json"),
    ("view-video-is-the-file", ["view", "{T}/walk.bvh", "--video", "{T}/walk.bvh"], "walk.bvh"),
    ("coverage-json-is-the-png", ["coverage", "--manifest", "{T}/manifest.json", "--json", "{T}/c.out", "--png",
                                  "{T}/c.out"], "c.out"),
    ("check-data-json-is-the-png", ["check-data", "--manifest", "{T}/manifest.json", "--quiet", "--json",
                                    "{T}/c.out", "--png", "{T}/c.out"], "c.out"),
    ("physics-png-is-the-json", ["physics", "{T}/walk.bvh", "--json", "{T}/p.out", "--png", "{T}/p.out"], "p.out"),
    ("eval-search-json-is-a-link-to-dev-null", ["eval-search", "--json", "{T}/null"], "null"),
    ("ab-report-is-the-tuning", ["ab", "{T}/s.lmmsession", "--tuning", "{T}/preset.json", "--report",
                                 "{T}/preset.json", "--quiet"], "preset.json"),
    ("input-from-json-is-the-manifest", ["input-from", "{T}/walk.bvh", "--manifest", "{T}/manifest.json", "--out",
                                         "{T}.out/o.csv", "--json", "{T}/manifest.json"], "manifest.json"),
]

# special files and non-ASCII numbers given as inputs: (id, argv, a word the error line must hold)
SPECIAL_INPUTS = [
    ("run-input-fifo", ["run", "--input", "{T}/fifo", "--quiet"], "fifo"),
    ("run-input-dev-zero", ["run", "--input", "/dev/zero", "--quiet"], "/dev/zero"),
    ("run-tuning-fifo", _RUN + ["--tuning", "{T}/fifo"], "fifo"),
    ("run-tuning-dev-zero", _RUN + ["--tuning", "/dev/zero"], "/dev/zero"),
    ("run-manifest-fifo", _RUN + ["--manifest", "{T}/fifo"], "fifo"),
    ("run-events-fifo", _RUN + ["--events", "{T}/fifo"], "fifo"),
    ("run-weights-fifo", ["run", "--controller", "lmm", "--weights", "{T}/fifo", "--input", "builtin:circle",
                          "--seconds", "1", "--quiet"], "fifo"),
    ("run-builtin-random-arabic-indic-seed", ["run", "--input", "builtin:random:\u0663", "--quiet"], "random"),
    ("run-input-non-ascii-digit", ["run", "--input", "{T}/digits.csv", "--quiet"], "digits.csv"),
    ("run-input-digit-grouping", ["run", "--input", "{T}/grouping.csv", "--quiet"], "grouping.csv"),
    ("build-db-manifest-fifo", ["build-db", "--manifest", "{T}/fifo", "--quiet"], "fifo"),
    # a manifest in {T} pointing at a special or broken file: (case, manifest, word)
    *[(f"build-db-{case}", ["build-db", "--manifest", f"{{T}}/{manifest}.json", "--quiet"], word)
      for case, manifest, word in (("features-fifo", "m_features_fifo", "features"),
                                   ("features-dev-zero", "m_features_zero", "features"),
                                   ("features-loop", "m_features_loop", "features"),
                                   ("clip-fifo", "m_clip_fifo", "clips"), ("clip-loop", "m_clip_loop", "clips"),
                                   ("bvh-digit-grouping", "m_grouping", "grouping.bvh"),
                                   ("bvh-non-ascii-digit", "m_digits", "digits.bvh"))],
    ("check-data-manifest-fifo", ["check-data", "--manifest", "{T}/fifo", "--quiet"], "fifo"),
    ("view-fifo", ["view", "{T}/fifo", "--screenshot", "{T}/shot.png"], "fifo"),
    ("compare-fifo", ["compare", "{T}/fifo", "{good}/walk.bvh"], "fifo"),
    ("input-from-fifo", ["input-from", "{T}/fifo", "--out", "{T}/o.csv"], "fifo"),
    ("physics-fifo", ["physics", "{T}/fifo"], "fifo"),
    ("run-manifest-dev-zero", _RUN + ["--manifest", "/dev/zero"], "/dev/zero"),
    ("run-events-dev-urandom", _RUN + ["--events", "/dev/urandom"], "/dev/urandom"),
    ("eval-weights-fifo", ["eval", "--weights", "{T}/fifo", "--seconds", "1", "--queries", "64"], "fifo"),
    ("export-onnx-weights-fifo", ["export-onnx", "--weights", "{T}/fifo", "--out", "{T}.out"], "fifo"),
    ("replay-session-fifo", ["replay", "{T}/fifo", "--quiet"], "fifo"),
    ("input-from-manifest-fifo", ["input-from", "{good}/walk.bvh", "--manifest", "{T}/fifo", "--out", "{T}.out/o.csv"],
     "fifo"),
    ("find-in-fifo", ["find", "{good}/walk.bvh", "--frames", "0:30", "--in", "{T}/fifo", "--quiet"], "fifo"),
    ("find-query-fifo", ["find", "{T}/fifo", "--frames", "0:30", "--in", "{good}/manifest.json", "--quiet"], "fifo"),
    # every other file argument: a FIFO, /dev/zero or /dev/urandom
    ("run-input-dev-urandom", ["run", "--input", "/dev/urandom", "--quiet"], "/dev/urandom"),
    ("run-weights-dev-zero", ["run", "--controller", "lmm", "--weights", "/dev/zero", "--input", "builtin:circle",
                              "--seconds", "1", "--quiet"], "/dev/zero"),
    ("build-db-manifest-dev-zero", ["build-db", "--manifest", "/dev/zero", "--quiet"], "/dev/zero"),
    ("check-data-manifest-dev-zero", ["check-data", "--manifest", "/dev/zero", "--quiet"], "/dev/zero"),
    ("coverage-manifest-fifo", ["coverage", "--manifest", "{T}/fifo", "--json", "{T}.out/c.json"], "fifo"),
    ("coverage-manifest-dev-zero", ["coverage", "--manifest", "/dev/zero", "--json", "{T}.out/c.json"], "/dev/zero"),
    ("train-manifest-fifo", ["train", "decompressor", "--manifest", "{T}/fifo", "--out", "{T}.out/w", "--iterations",
                             "1", "--quiet"], "fifo"),
    ("train-manifest-dev-zero", ["train", "decompressor", "--manifest", "/dev/zero", "--out", "{T}.out/w",
                                 "--iterations", "1", "--quiet"], "/dev/zero"),
    ("eval-weights-dev-zero", ["eval", "--weights", "/dev/zero", "--seconds", "1", "--queries", "64"], "/dev/zero"),
    ("eval-compressor-fifo", ["eval", "--weights", "{T}/w.npz", "--compressor", "{T}/fifo", "--seconds", "1",
                              "--queries", "64"], "fifo"),
    ("eval-input-fifo", ["eval", "--input", "{T}/fifo", "--seconds", "1", "--queries", "64"], "fifo"),
    ("eval-manifest-fifo", ["eval", "--manifest", "{T}/fifo", "--seconds", "1", "--queries", "64"], "fifo"),
    ("eval-heldout-fifo", ["eval", "--reconstruction", "--heldout", "{T}/fifo"], "fifo"),
    ("export-onnx-weights-dev-zero", ["export-onnx", "--weights", "/dev/zero", "--out", "{T}.out/o"], "/dev/zero"),
    ("view-dev-zero", ["view", "/dev/zero", "--screenshot", "{T}.out/s.png"], "/dev/zero"),
    ("compare-second-fifo", ["compare", "{good}/walk.bvh", "{T}/fifo"], "fifo"),
    ("physics-dev-zero", ["physics", "/dev/zero"], "/dev/zero"),
    ("export-gltf-fifo", ["export-gltf", "{T}/fifo", "--out", "{T}.out/x.glb"], "fifo"),
    ("bench-manifest-fifo", ["bench", "--manifest", "{T}/fifo"], "fifo"),
    ("replay-session-dev-zero", ["replay", "/dev/zero", "--quiet"], "/dev/zero"),
    ("replay-tuning-fifo", ["replay", "{T}/s.lmmsession", "--tuning", "{T}/fifo", "--quiet"], "fifo"),
    ("replay-manifest-fifo", ["replay", "{T}/s.lmmsession", "--manifest", "{T}/fifo", "--quiet"], "fifo"),
    ("trace-session-fifo", ["trace", "{T}/fifo", "--out", "{T}.out/t.csv", "--quiet"], "fifo"),
    ("ab-session-fifo", ["ab", "{T}/fifo", "--tuning", "{T}/preset.json", "--quiet"], "fifo"),
    ("ab-tuning-fifo", ["ab", "{T}/s.lmmsession", "--tuning", "{T}/fifo", "--quiet"], "fifo"),
    ("studio-open-fifo", ["studio", "--open", "{T}/fifo", "--frames", "1"], "fifo"),
    ("eval-search-data-fifo", ["eval-search", "--data", "{T}/fifo"], "fifo"),
    ("eval-search-encoder-fifo", ["eval-search", "--encoder", "{T}/fifo"], "fifo"),
    ("eval-search-classifier-dev-zero", ["eval-search", "--classifier", "/dev/zero"], "/dev/zero"),
    ("trace-manifest-fifo", ["trace", "{T}/s.lmmsession", "--manifest", "{T}/fifo", "--out", "{T}.out/t.csv",
                             "--quiet"], "fifo"),
    ("ab-manifest-fifo", ["ab", "{T}/s.lmmsession", "--tuning", "{T}/preset.json", "--manifest", "{T}/fifo",
                          "--quiet"], "fifo"),
    ("export-gltf-dev-zero", ["export-gltf", "/dev/zero", "--out", "{T}.out/x.glb"], "/dev/zero"),
]

#: the cases that read a valid session ({T}/s.lmmsession, a copy of the corpus's generated one)
NEEDS_SESSION = {cid for cid, argv, _ in COLLISIONS + SPECIAL_INPUTS if "{T}/s.lmmsession" in argv}


# weights within every load limit whose networks give NaN or runaway poses: the run goes on (exit 0),
# says so in one note naming the first tick, and records none of those poses: (id, {array: value})
ADVERSARIAL_WEIGHTS = [
    ("stepper-1e4", {"stepper.W": 1e4, "stepper.out_std": 1e4}),
    ("stepper-in-std-1e-38", {"stepper.in_std": 1e-38}),
    ("decompressor-1e4", {"decompressor.W": 1e4}),
    ("projector-1e4", {"projector.W": 1e4}),
]
NOTES = [(f"run-weights-{cid}", ["run", "--controller", "lmm", "--weights", "{T}/adversarial.npz", "--input",
                                 "builtin:circle", "--seconds", "1", "--quiet", "--record", "{T}.out/take.bvh"],
          "note: tick") for cid, _ in ADVERSARIAL_WEIGHTS]


def make_adversarial(T: Path, name: str) -> None:
    """``T/adversarial.npz``: the shipped weights changed as :data:`ADVERSARIAL_WEIGHTS` ``name`` says."""
    import numpy as np

    change = dict(ADVERSARIAL_WEIGHTS)[name]
    with np.load(WEIGHTS, allow_pickle=False) as z:
        arrays = {k: z[k] for k in z.files}
    for key in arrays:
        for prefix, value in change.items():
            if key.startswith(prefix):
                arrays[key] = np.full_like(arrays[key], value)
    np.savez(T / "adversarial.npz", **arrays)


def _manifest(T: Path, name: str, **change) -> None:
    m = json.loads((GOOD / "manifest.json").read_text())
    m["clips"] = [{"file": "walk.bvh"}]
    m.update(change)
    (T / name).write_text(json.dumps(m))


def _bvh_with_value(T: Path, name: str, value: str) -> None:
    """walk.bvh with its last motion value replaced by ``value``."""
    text = (GOOD / "walk.bvh").read_text().rstrip("\n")
    head, _, last = text.rpartition(" ")
    (T / name).write_text(f"{head} {value}\n")


def prepare(T: Path, case_id: str) -> None:
    """The case folder: copies of the good files and the special files the cases name."""
    T.mkdir(parents=True, exist_ok=True)
    for name in ("input.csv", "preset.json", "walk.bvh"):
        shutil.copyfile(GOOD / name, T / name)
    shutil.copyfile(GOOD / "input.csv", T / "take.input.csv")
    _manifest(T, "manifest.json")
    if "weights" in case_id or "eval" in case_id or case_id.startswith("export-onnx"):
        shutil.copyfile(WEIGHTS, T / "w.npz")
    if case_id.startswith("run-weights-") and case_id[len("run-weights-"):] in dict(ADVERSARIAL_WEIGHTS):
        make_adversarial(T, case_id[len("run-weights-"):])
    if case_id.startswith("export-onnx"):
        shutil.copyfile(WEIGHTS, T / "decompressor.onnx")
    if "compressor" in case_id:
        shutil.copyfile(WEIGHTS.with_name("compressor.npz"), T / "compressor.npz")
    os.mkfifo(T / "fifo")
    (T / "null").symlink_to(os.devnull)
    os.link(T / "input.csv", T / "hard.csv")
    os.link(T / "walk.bvh", T / "hard.bvh")
    (T / "loop").symlink_to(T / "loop")
    (T / "trainout").mkdir()
    os.mkfifo(T / "trainout" / "default.npz")
    _manifest(T, "m_features_fifo.json", features="fifo")
    _manifest(T, "m_features_zero.json", features="/dev/zero")
    _manifest(T, "m_features_loop.json", features="loop")
    _manifest(T, "m_clip_fifo.json", clips=[{"file": "fifo"}])
    _manifest(T, "m_clip_loop.json", clips=[{"file": "loop"}])
    rows = (GOOD / "input.csv").read_text().splitlines()
    (T / "digits.csv").write_text("\n".join(rows[:2] + ["\u0661," + rows[2].split(",", 1)[1]]) + "\n")
    (T / "grouping.csv").write_text("\n".join(rows[:2] + ["1_0," + rows[2].split(",", 1)[1]]) + "\n")
    _bvh_with_value(T, "grouping.bvh", "1_0.0")
    _bvh_with_value(T, "digits.bvh", "\u0661\u0662")
    _manifest(T, "m_grouping.json", clips=[{"file": "grouping.bvh"}])
    _manifest(T, "m_digits.json", clips=[{"file": "digits.bvh"}])


def fingerprint(T: Path) -> dict:
    """Every entry under ``T`` by :func:`fingerprint_of` (relative paths)."""
    out = {}
    for dirpath, dirnames, filenames in os.walk(T):
        for name in filenames + [d for d in dirnames if os.path.islink(os.path.join(dirpath, d))]:
            p = os.path.join(dirpath, name)
            out[os.path.relpath(p, T)] = fingerprint_of(p)
    return out


def fingerprint_of(p) -> str:
    """A regular file by its content's hash (read in pieces: a case file may be a 1 GiB sparse one),
    anything else by its kind, a link by its target and the kind of what it points at, a missing path
    as missing."""
    import hashlib
    import stat

    try:
        st = os.lstat(p)
    except FileNotFoundError:
        return "missing"
    if stat.S_ISLNK(st.st_mode):
        try:
            target_mode = stat.S_IFMT(os.stat(p).st_mode)
        except OSError:
            target_mode = None
        return f"link -> {os.readlink(p)} ({target_mode})"
    if stat.S_ISREG(st.st_mode):
        h = hashlib.sha256()
        with open(p, "rb") as f:
            for chunk in iter(lambda: f.read(1 << 20), b""):
                h.update(chunk)
        return h.hexdigest()
    return f"mode {stat.S_IFMT(st.st_mode)}"

"""The C++ reference for ``bench``'s network figures, measured in the same run on the same machine.

``nnet_reference.cpp`` (next to this file) evaluates a network the way the reference demo's runtime does
(plain loops, zero inputs skipped, -O3 -ffast-math). :func:`measure` builds it once per source into the
cache (``<cache>/bench/``), writes our networks and real inputs to a file and returns the median per-call
time of each network. Without a C++ compiler, or when the build or the run fails, it returns None with a
one-line reason, and ``bench`` falls back to the figures the issue measured on another machine.
"""
from __future__ import annotations

import hashlib
import json
import os
import shutil
import struct
import subprocess
import tempfile
from pathlib import Path

import numpy as np

SOURCE = Path(__file__).with_name("nnet_reference.cpp")
#: the reference demo's release build flags
FLAGS = ["-O3", "-ffast-math", "-DNDEBUG"]


def compiler() -> str | None:
    for name in (os.environ.get("CXX"), "g++", "clang++", "c++"):
        if name and shutil.which(name):
            return shutil.which(name)
    return None


def build(cache_dir: Path) -> Path:
    """The compiled reference program (built on first use, keyed by the source, flags and compiler)."""
    cxx = compiler()
    if cxx is None:
        raise RuntimeError("no C++ compiler (g++, clang++ or $CXX) on PATH")
    key = hashlib.sha256(SOURCE.read_bytes() + " ".join([cxx, *FLAGS]).encode()).hexdigest()[:16]
    exe = Path(cache_dir) / "bench" / f"nnet_reference-{key}"
    if exe.exists():
        return exe
    exe.parent.mkdir(parents=True, exist_ok=True)
    tmp = exe.with_name(exe.name + f".{os.getpid()}.tmp")
    proc = subprocess.run([cxx, *FLAGS, "-o", str(tmp), str(SOURCE)], capture_output=True, text=True, timeout=120)
    if proc.returncode != 0:
        tmp.unlink(missing_ok=True)
        first = (proc.stderr.strip().splitlines() or ["no message"])[0]
        raise RuntimeError(f"{SOURCE.name}: build failed: {first[:200]}")
    os.replace(tmp, exe)
    return exe


def write_networks(path: Path, networks: dict, samples: dict) -> None:
    """``networks``: name -> :class:`lmm.nn.MLP` (ReLU); ``samples``: name -> float32 (S, n_in) inputs.
    The file layout is described at the top of ``nnet_reference.cpp``."""
    def arr(a) -> bytes:
        return np.ascontiguousarray(a, dtype="<f4").tobytes()

    parts = [b"LMMNB1", struct.pack("<i", len(networks))]
    for name, net in networks.items():
        if net.activation != "relu":
            raise ValueError(f"{name}: the C++ reference evaluates ReLU networks only, not {net.activation}")
        x = np.asarray(samples[name], np.float32).reshape(-1, net.n_in)
        raw = name.encode()
        parts += [struct.pack("<i", len(raw)), raw, struct.pack("<iii", int(net.skip), len(net.weights), net.n_in),
                  arr(net.in_mean), arr(1.0 / net.in_inv_std), struct.pack("<i", net.n_out),
                  arr(net.out_mean), arr(net.out_std)]
        for w, b in zip(net.weights, net.biases):
            parts += [struct.pack("<ii", *w.shape), arr(w), arr(b)]
        parts += [struct.pack("<i", x.shape[0]), arr(x)]
    Path(path).write_bytes(b"".join(parts))


def measure(networks: dict, samples: dict, cache_dir: Path, repeats: int = 2000) -> tuple[dict | None, str]:
    """(name -> median per-call us, "") from the compiled reference, or (None, reason)."""
    try:
        exe = build(cache_dir)
        with tempfile.TemporaryDirectory(prefix="lmm-nnet-") as tmp:
            data = Path(tmp) / "networks.bin"
            write_networks(data, networks, samples)
            proc = subprocess.run([str(exe), str(data), str(int(repeats))], capture_output=True, text=True, timeout=300)
        if proc.returncode != 0:
            return None, f"{exe.name}: {(proc.stderr.strip().splitlines() or ['failed'])[0][:200]}"
        out = json.loads(proc.stdout)
        times = {}
        for name, net in networks.items():
            # the timed computation must be ours: the first sample's outputs agree to float32 rounding
            ours = net(np.asarray(samples[name], np.float32).reshape(-1, net.n_in)[:1])[0]
            theirs = np.asarray(out[name]["y0"], np.float32)
            scale = float(np.max(np.abs(ours))) + 1e-6
            if theirs.shape != ours.shape or float(np.max(np.abs(theirs - ours))) > 1e-4 * scale:
                return None, f"{name}: the C++ outputs differ from ours (max {float(np.max(np.abs(theirs - ours))):.3g})"
            times[name] = float(out[name]["us"])
        return times, ""
    except (OSError, RuntimeError, ValueError, KeyError, TypeError, subprocess.SubprocessError) as e:
        return None, str(e)

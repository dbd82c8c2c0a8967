"""The C++ references of ``bench``, built with the reference demo's flags and measured in the same run.

``nnet_reference.cpp`` (next to this file) evaluates a network the way the reference demo's runtime does
(plain loops, zero inputs skipped; ``nnet_reference.h``); ``frame_reference.cpp`` runs whole motion
matching and learned motion matching frames (:mod:`app.commands.bench_frame_reference`). Both are built
with :data:`FLAGS`, the demo's own Makefile flags, once per source into the cache (``<cache>/bench/``).
:func:`measure` writes our networks and real inputs to a file and returns the median per-call time of
each network. Without a C++ compiler (``$CXX`` when set, else g++, clang++ or c++ on PATH), or when a
build or a run fails, the figures are None with a one-line reason.
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
#: the headers the reference programs include (part of each build's key)
HEADERS = [Path(__file__).with_name(n) for n in ("nnet_reference.h", "frame_pose.h", "frame_character.h")]
#: the reference demo's build flags, as its Makefile gives them (issue 38: without -march=native its code
#: ran 1.6-1.8x slower); the programs are built for the CPU they run on, so the CPU is part of the key
FLAGS = ["-O3", "-ffast-math", "-march=native"]


def compiler() -> str | None:
    """The C++ compiler: ``$CXX`` when set (only it: a ``$CXX`` that is not there means none), else the
    first of g++, clang++ and c++ on PATH."""
    chosen = os.environ.get("CXX")
    for name in ([chosen] if chosen else ["g++", "clang++", "c++"]):
        if shutil.which(name):
            return shutil.which(name)
    return None


def _cpu_model() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8", errors="replace") as f:
            return next((ln for ln in f if ln.startswith(("model name", "flags"))), "")
    except OSError:
        return ""


def build(cache_dir: Path, source: Path = SOURCE) -> Path:
    """The compiled reference program of ``source`` (built on first use, keyed by the sources, flags,
    compiler and CPU)."""
    cxx = compiler()
    if cxx is None:
        raise RuntimeError("no C++ compiler ($CXX, or g++, clang++ or c++ on PATH)")
    text = source.read_bytes() + b"".join(h.read_bytes() for h in HEADERS if h.exists())
    key = hashlib.sha256(text + " ".join([cxx, *FLAGS, _cpu_model()]).encode()).hexdigest()[:16]
    exe = Path(cache_dir) / "bench" / f"{source.stem}-{key}"
    if exe.exists():
        return exe
    exe.parent.mkdir(parents=True, exist_ok=True)
    tmp = exe.with_name(exe.name + f".{os.getpid()}.tmp")
    proc = subprocess.run([cxx, *FLAGS, "-o", str(tmp), str(source)], capture_output=True, text=True, timeout=180)
    if proc.returncode != 0:
        tmp.unlink(missing_ok=True)
        first = (proc.stderr.strip().splitlines() or ["no message"])[0]
        raise RuntimeError(f"{source.name}: build failed: {first[:200]}")
    os.replace(tmp, exe)
    return exe


def write_networks(path: Path, networks: dict, samples: dict) -> None:
    """``networks``: name -> :class:`lmm.nn.MLP` (ReLU); ``samples``: name -> float32 (S, n_in) inputs.
    The file layout is described at the top of ``nnet_reference.cpp``."""
    parts = [b"LMMNB1", struct.pack("<i", len(networks))]
    parts += network_blocks(networks, samples)
    Path(path).write_bytes(b"".join(parts))


def f32(a) -> bytes:
    """Little-endian float32 bytes of ``a``."""
    return np.ascontiguousarray(a, dtype="<f4").tobytes()


def network_blocks(networks: dict, samples: dict) -> list[bytes]:
    """One block per network, as ``nnet_reference.h`` reads them."""
    parts = []
    for name, net in networks.items():
        if net.activation != "relu":
            raise ValueError(f"{name}: the C++ reference evaluates ReLU networks only, not {net.activation}")
        x = np.asarray(samples[name], np.float32).reshape(-1, net.n_in)
        raw = name.encode()
        parts += [struct.pack("<i", len(raw)), raw, struct.pack("<iii", int(net.skip), len(net.weights), net.n_in),
                  f32(net.in_mean), f32(1.0 / net.in_inv_std), struct.pack("<i", net.n_out),
                  f32(net.out_mean), f32(net.out_std)]
        for w, b in zip(net.weights, net.biases):
            parts += [struct.pack("<ii", *w.shape), f32(w), f32(b)]
        parts += [struct.pack("<i", x.shape[0]), f32(x)]
    return parts


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

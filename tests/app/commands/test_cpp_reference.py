"""The same-run C++ network reference of ``lmm-studio bench`` (app/commands/cpp_reference.py)."""
import subprocess

import numpy as np
import pytest

from app.commands import cpp_reference
from lmm.nn import MLP

pytestmark = pytest.mark.skipif(cpp_reference.compiler() is None, reason="no C++ compiler")


def _mlp(rng, sizes, skip=False, activation="relu"):
    ws = [rng.standard_normal((a, b)).astype(np.float32) * 0.3 for a, b in zip(sizes[:-1], sizes[1:])]
    bs = [rng.standard_normal(b).astype(np.float32) * 0.1 for b in sizes[1:]]
    return MLP(ws, bs, activation, rng.standard_normal(sizes[0]), rng.random(sizes[0]) + 0.5,
               rng.standard_normal(sizes[-1]), rng.random(sizes[-1]) + 0.5, skip=skip)


def test_times_the_same_computation_as_ours(tmp_path):
    rng = np.random.default_rng(3)
    nets = {"plain": _mlp(rng, [7, 32, 32, 5]), "skip": _mlp(rng, [6, 16, 9], skip=True)}
    samples = {name: rng.standard_normal((4, net.n_in)).astype(np.float32) for name, net in nets.items()}
    times, why = cpp_reference.measure(nets, samples, tmp_path, repeats=50)
    assert why == "" and set(times) == set(nets) and all(t > 0 for t in times.values())
    assert len(list((tmp_path / "bench").glob("nnet_reference-*"))) == 1     # built once, kept


def test_outputs_that_differ_from_ours_are_refused(tmp_path):
    class Off(MLP):
        def __call__(self, x, out=None):
            return super().__call__(x, out) + 1.0

    rng = np.random.default_rng(4)
    good = _mlp(rng, [5, 8, 3])
    bad = Off(good.weights, good.biases, "relu", good.in_mean, 1.0 / good.in_inv_std, good.out_mean, good.out_std)
    times, why = cpp_reference.measure({"bad": bad}, {"bad": np.ones((2, 5), np.float32)}, tmp_path, repeats=10)
    assert times is None and "bad: the C++ outputs differ from ours" in why


def test_elu_networks_are_refused_with_a_reason(tmp_path):
    net = _mlp(np.random.default_rng(5), [4, 8, 2], activation="elu")
    times, why = cpp_reference.measure({"e": net}, {"e": np.zeros((1, 4), np.float32)}, tmp_path, repeats=10)
    assert times is None and "ReLU networks only" in why


@pytest.mark.parametrize("cut", [3, 20, -7])
def test_a_broken_network_file_is_one_line_naming_it(tmp_path, cut):
    rng = np.random.default_rng(6)
    net = _mlp(rng, [4, 8, 2])
    good = tmp_path / "good.bin"
    cpp_reference.write_networks(good, {"n": net}, {"n": np.zeros((2, 4), np.float32)})
    bad = tmp_path / "bad.bin"
    bad.write_bytes(good.read_bytes()[:cut])
    exe = cpp_reference.build(tmp_path)
    r = subprocess.run([str(exe), str(bad), "5"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and r.stdout == ""
    assert len(r.stderr.strip().splitlines()) == 1 and str(bad) in r.stderr
    r = subprocess.run([str(exe), str(good), "5"], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0 and '"n": {"us": ' in r.stdout

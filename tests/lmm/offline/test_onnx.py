"""ONNX export of the runtime networks, checked with onnxruntime against the numpy runtime."""
import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
ort = pytest.importorskip("onnxruntime")

from lmm.learned import DEFAULT_WEIGHTS, LMMNetworks  # noqa: E402
from lmm.nn import MLP  # noqa: E402
from lmm.offline.onnx_export import export_networks, mlp_to_onnx  # noqa: E402


def run_onnx(path_or_model, x):
    data = path_or_model if isinstance(path_or_model, (str, bytes)) else path_or_model.SerializeToString()
    sess = ort.InferenceSession(data, providers=["CPUExecutionProvider"])
    return sess.run(None, {"x": x})[0]


@pytest.mark.parametrize("activation,skip", [("relu", False), ("elu", False), ("relu", True)])
def test_small_graph_matches_numpy(activation, skip):
    rng = np.random.default_rng(0)
    sizes = [7, 16, 16, 9]
    mlp = MLP([rng.normal(size=(a, b)).astype(np.float32) for a, b in zip(sizes[:-1], sizes[1:])],
              [rng.normal(size=b).astype(np.float32) for b in sizes[1:]], activation,
              rng.normal(size=7), rng.uniform(0.5, 2, 7), rng.normal(size=9), rng.uniform(0.5, 2, 9), skip=skip)
    x = rng.normal(size=(9, 7)).astype(np.float32)
    assert np.max(np.abs(run_onnx(mlp_to_onnx(mlp, "t"), x) - mlp(x))) < 1e-4


def test_export_command_and_shipped_networks(tmp_path):
    if not DEFAULT_WEIGHTS.exists():
        pytest.skip("no shipped weights")
    from app.cli import main
    assert main(["export-onnx", "--out", str(tmp_path)]) == 0
    nets = LMMNetworks.load(DEFAULT_WEIGHTS)
    rng = np.random.default_rng(1)
    for name in ("decompressor", "stepper", "projector"):
        mlp = getattr(nets, name)
        path = tmp_path / f"{name}.onnx"
        model = onnx.load(str(path))
        assert {p.key for p in model.metadata_props} >= {"database_key", "feature_layout"}
        x = rng.normal(size=(32, mlp.n_in)).astype(np.float32)
        assert np.max(np.abs(run_onnx(str(path), x) - mlp(x))) < 1e-4, name
        assert np.max(np.abs(run_onnx(str(path), x[:1]) - mlp(x[0])[None])) < 1e-4, name

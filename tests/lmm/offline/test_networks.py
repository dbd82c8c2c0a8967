"""The torch networks: layouts, parameter counts, normalisation, and the numpy runtime reproducing them."""
import numpy as np
import pytest

torch = pytest.importorskip("torch")

from lmm.offline.networks import MLPSpec, NormalizedMLP, default_specs  # noqa: E402
from lmm.nn import MLP  # noqa: E402


def test_default_layouts_match_the_paper():
    specs = default_specs()
    assert specs["compressor"].sizes == [668, 512, 512, 512, 32] and specs["compressor"].activation == "elu"
    assert specs["decompressor"].sizes == [59, 512, 338]
    assert specs["stepper"].sizes == [59, 512, 512, 59]
    assert specs["projector"].sizes == [27, 512, 512, 512, 512, 59] and specs["projector"].skip
    counts = {n: NormalizedMLP(s).parameter_count() for n, s in specs.items()}
    # Table 1 of the paper / reference notes: ~884k, ~204k, ~324k, ~833k
    assert abs(counts["compressor"] - 884_000) < 10_000
    assert abs(counts["decompressor"] - 204_000) < 5_000
    assert abs(counts["stepper"] - 324_000) < 5_000
    assert abs(counts["projector"] - 833_000) < 10_000


def test_spec_roundtrip_and_bad_activation():
    s = MLPSpec(3, (4, 5), 2, "elu")
    assert MLPSpec.from_dict(s.to_dict()) == s
    assert MLPSpec.from_dict(MLPSpec(3, (4,), 5, skip=True).to_dict()).skip
    assert not MLPSpec.from_dict({"n_in": 3, "hidden": [4], "n_out": 2}).skip  # files from before skips
    with pytest.raises(ValueError):
        MLPSpec(3, (4,), 2, "tanh")
    with pytest.raises(ValueError, match="skip"):
        MLPSpec(5, (4,), 3, skip=True)


@pytest.mark.parametrize("activation,skip", [("relu", False), ("elu", False), ("relu", True)])
def test_numpy_runtime_matches_torch(activation, skip):
    torch.manual_seed(0)
    net = NormalizedMLP(MLPSpec(27, (64, 64), 59, activation, skip))
    rng = np.random.default_rng(0)
    net.set_normalization(rng.normal(size=27), rng.uniform(0.5, 2, 27), rng.normal(size=59), rng.uniform(0.5, 2, 59))
    mlp = MLP.from_spec(net.to_arrays("p"), "p", net.spec.to_dict())
    assert mlp.skip == skip
    x = rng.normal(size=(16, 27)).astype(np.float32)
    with torch.no_grad():
        ref = net(torch.from_numpy(x)).numpy()
    assert np.max(np.abs(mlp(x) - ref)) < 1e-4
    assert np.max(np.abs(mlp(x[3]) - ref[3])) < 1e-4  # batch 1 path
    out = np.zeros(59, np.float32)
    mlp(x[5], out=out)
    assert np.max(np.abs(out - ref[5])) < 1e-4


def test_skip_adds_the_input_to_the_first_outputs():
    net = NormalizedMLP(MLPSpec(3, (4,), 5, skip=True))
    with torch.no_grad():
        net.layers[-1].weight.zero_()
        net.layers[-1].bias.zero_()
    x = torch.tensor([[1.0, -2.0, 3.0]])
    assert torch.equal(net(x), torch.tensor([[1.0, -2.0, 3.0, 0.0, 0.0]]))
    mlp = MLP.from_spec(net.to_arrays("s"), "s", net.spec.to_dict())
    assert np.array_equal(mlp(x.numpy()[0]), [1.0, -2.0, 3.0, 0.0, 0.0])


def test_load_arrays_roundtrip():
    a = NormalizedMLP(MLPSpec(5, (7,), 3))
    b = NormalizedMLP(MLPSpec(5, (7,), 3))
    b.load_arrays(a.to_arrays("n"), "n")
    x = torch.randn(4, 5)
    assert torch.allclose(a(x), b(x))

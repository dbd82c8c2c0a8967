"""Weight files: round trip, and real broken files each give a clear WeightsError naming file and problem."""
import json

import numpy as np
import pytest

from lmm.data import weights as W

SPECS = {"decompressor": {"n_in": 59, "hidden": [8], "n_out": 338, "activation": "relu"},
         "stepper": {"n_in": 59, "hidden": [8, 8], "n_out": 59, "activation": "relu"},
         "projector": {"n_in": 27, "hidden": [8], "n_out": 59, "activation": "relu"}}
LAYOUT = [{"name": f"c{i}", "kind": "bone_position", "bone": "b", "weight": 1.0} for i in range(9)]


def make_arrays(specs=SPECS, seed=0):
    rng = np.random.default_rng(seed)
    out = {}
    for name, spec in specs.items():
        for key, shape in W.expected_shapes(name, spec).items():
            out[key] = (np.abs(rng.normal(size=shape)) + 0.5).astype(np.float32)
    return out


def metadata():
    return {"networks": SPECS, "database_key": "a" * 64, "feature_layout": LAYOUT, "latent": 32,
            "feature_mean": [0.0] * 27, "feature_inv_scale": [1.0] * 27, "n_bones": 23}


@pytest.fixture
def good(tmp_path):
    return W.save(tmp_path / "good.npz", make_arrays(), metadata())


def test_roundtrip(good):
    wf = W.load(good, db_key="a" * 64, layout_dicts=LAYOUT)
    assert sorted(wf.networks) == ["decompressor", "projector", "stepper"]
    ref = make_arrays()
    for k, v in ref.items():
        np.testing.assert_array_equal(wf.arrays[k], v)
    # weights only rescale: a layout differing in weights still matches
    W.load(good, layout_dicts=[dict(d, weight=3.0) for d in LAYOUT])


def test_no_pickle_inside(good):
    with np.load(good, allow_pickle=False) as z:
        for k in z.files:
            assert z[k].dtype != object


def test_missing_file(tmp_path):
    with pytest.raises(W.WeightsError, match="not found") as e:
        W.load(tmp_path / "nope.npz")
    assert "nope.npz" in str(e.value)


@pytest.mark.parametrize("fraction", [0.0, 0.3, 0.9, 0.999])
def test_truncated(good, tmp_path, fraction):
    data = good.read_bytes()
    bad = tmp_path / "truncated.npz"
    bad.write_bytes(data[:int(len(data) * fraction)])
    with pytest.raises(W.WeightsError, match="truncated or corrupt") as e:
        W.load(bad)
    assert "truncated.npz" in str(e.value)


def test_corrupt_bytes(good, tmp_path):
    data = bytearray(good.read_bytes())
    data[len(data) // 2:len(data) // 2 + 64] = b"\xff" * 64
    bad = tmp_path / "corrupt.npz"
    bad.write_bytes(bytes(data))
    with pytest.raises(W.WeightsError) as e:
        W.load(bad)
    assert "corrupt.npz" in str(e.value)


def test_not_a_weights_file(tmp_path):
    p = tmp_path / "other.npz"
    np.savez(p, a=np.zeros(3))
    with pytest.raises(W.WeightsError, match="no metadata"):
        W.load(p)


def _write_raw(path, arrays, meta):
    arrays = dict(arrays)
    arrays["metadata"] = np.frombuffer(json.dumps(dict(meta, format_version=W.WEIGHTS_FORMAT_VERSION)).encode(), np.uint8)
    np.savez(path, **arrays)
    return path


def test_nan_weights(tmp_path):
    arrays = make_arrays()
    arrays["stepper.W1"][2, 3] = np.nan
    p = _write_raw(tmp_path / "nan.npz", arrays, metadata())
    with pytest.raises(W.WeightsError, match=r"stepper\.W1 holds 1 NaN/inf") as e:
        W.load(p)
    assert "nan.npz" in str(e.value)


def test_inf_weights(tmp_path):
    arrays = make_arrays()
    arrays["projector.b0"][0] = np.inf
    with pytest.raises(W.WeightsError, match="NaN/inf"):
        W.load(_write_raw(tmp_path / "inf.npz", arrays, metadata()))


def test_wrong_shape(tmp_path):
    arrays = make_arrays()
    arrays["decompressor.W0"] = arrays["decompressor.W0"][:, :7]
    p = _write_raw(tmp_path / "shape.npz", arrays, metadata())
    with pytest.raises(W.WeightsError, match=r"decompressor\.W0 has shape \(59, 7\), expected \(59, 8\)") as e:
        W.load(p)
    assert "shape.npz" in str(e.value)


def test_missing_array(tmp_path):
    arrays = make_arrays()
    del arrays["projector.out_std"]
    with pytest.raises(W.WeightsError, match=r"missing array projector\.out_std"):
        W.load(_write_raw(tmp_path / "missing.npz", arrays, metadata()))


def test_missing_network(good):
    with pytest.raises(W.WeightsError, match="no compressor network"):
        W.load(good, require=["compressor"])


def test_other_database(good):
    with pytest.raises(W.WeightsError, match="trained on another database") as e:
        W.load(good, db_key="b" * 64)
    assert "good.npz" in str(e.value)


def test_other_layout(good):
    with pytest.raises(W.WeightsError, match="trained on another feature schema"):
        W.load(good, layout_dicts=LAYOUT[:-1])


def test_bad_metadata_json(tmp_path, good):
    arrays = make_arrays()
    arrays["metadata"] = np.frombuffer(b"{not json", np.uint8)
    p = tmp_path / "json.npz"
    np.savez(p, **arrays)
    with pytest.raises(W.WeightsError, match="metadata record is not valid JSON"):
        W.load(p)


def test_save_refuses_inconsistent(tmp_path):
    arrays = make_arrays()
    arrays["stepper.b0"] = np.zeros(3, np.float32)
    with pytest.raises(W.WeightsError, match="refusing to save"):
        W.save(tmp_path / "x.npz", arrays, metadata())


def test_shipped_weights_are_valid():
    from lmm.learned import DEFAULT_WEIGHTS
    if not DEFAULT_WEIGHTS.exists():
        pytest.skip("no shipped weights")
    wf = W.load(DEFAULT_WEIGHTS, require=["decompressor", "stepper", "projector"])
    assert wf.metadata["latent"] == 32
    assert DEFAULT_WEIGHTS.stat().st_size < 8 * 2**20


def _with_meta(tmp_path, change, name="m.npz"):
    import copy

    meta = copy.deepcopy(metadata())  # SPECS is shared
    meta["format_version"] = W.WEIGHTS_FORMAT_VERSION
    change(meta)
    p = tmp_path / name
    _write_raw(p, make_arrays(), meta)
    return p


@pytest.mark.parametrize("change, words", [
    (lambda m: m.pop("n_bones"), "metadata field 'n_bones': expected an integer in [1, 1024], got missing"),
    (lambda m: m.update(n_bones="abc"), "metadata field 'n_bones': expected an integer in [1, 1024], got 'abc'"),
    (lambda m: m.update(n_bones=True), "metadata field 'n_bones'"),
    (lambda m: m.update(latent="32"), "metadata field 'latent'"),
    (lambda m: m.update(latent=100), "metadata field 'latent': 100 leaves no features"),
    (lambda m: m.pop("feature_mean"), "metadata field 'feature_mean': expected a list of numbers, got missing"),
    (lambda m: m.update(feature_mean=[0.0] * 5), "metadata field 'feature_mean' has 5 entries"),
    (lambda m: m.update(feature_inv_scale=[0.0] * 27), "metadata field 'feature_inv_scale': entry 0 is 0"),
    (lambda m: m.update(feature_inv_scale=[1.0] * 26 + ["x"]), "expected a list of numbers"),
    (lambda m: m.update(feature_mean=[1e300] * 27), "metadata field 'feature_mean': entry 0 is 1e+300, outside"),
    (lambda m: m["networks"]["stepper"].update(hidden="512"), "'networks.stepper' 'hidden'"),
    (lambda m: m["networks"]["stepper"].update(hidden=[10 ** 9]), "'networks.stepper' 'hidden'"),
    (lambda m: m["networks"]["stepper"].pop("n_in"), "'networks.stepper' 'n_in': expected an integer"),
    (lambda m: m["networks"]["projector"].update(activation="tanh"), "'networks.projector' 'activation'"),
    (lambda m: m.update(networks=[1]), "metadata lists no networks"),
    (lambda m: m.update(feature_layout="x"), "metadata field 'feature_layout': expected a list"),
    (lambda m: m.update(recipe=[]), "metadata field 'recipe'"),
])
def test_malformed_metadata_names_the_field(tmp_path, change, words):
    p = _with_meta(tmp_path, change)
    with pytest.raises(W.WeightsError) as e:
        W.load(p)
    assert str(e.value).startswith(f"{p}: ") and words in str(e.value), str(e.value)


def test_metadata_not_an_object_or_too_deep(tmp_path):
    arrays = make_arrays()
    for name, text, words in (("list.npz", b"[1]", "not a JSON object"),
                              ("deep.npz", b"[" * 5000 + b"]" * 5000, "metadata record nested 5000 levels")):
        arrays["metadata"] = np.frombuffer(text, np.uint8)
        np.savez(tmp_path / name, **arrays)
        with pytest.raises(W.WeightsError, match=words):
            W.load(tmp_path / name)


@pytest.mark.parametrize("key, value, words", [
    ("stepper.W1", 3e38, "stepper.W1 holds values up to 3e+38, beyond +-10000"),
    ("decompressor.out_std", 0.0, "decompressor.out_std has non-positive entries"),
    ("projector.in_std", 0.0, "projector.in_std has non-positive entries"),
])
def test_absurd_arrays_are_refused(tmp_path, key, value, words):
    arrays = make_arrays()
    arrays[key][...] = value
    meta = dict(metadata(), format_version=W.WEIGHTS_FORMAT_VERSION)
    _write_raw(tmp_path / "a.npz", arrays, meta)
    with pytest.raises(W.WeightsError, match=words.replace("+", r"\+").replace(".", r"\.")):
        W.load(tmp_path / "a.npz")


def test_extra_and_oversized_members_are_never_read(tmp_path):
    import tracemalloc

    arrays = make_arrays()
    arrays["metadata"] = np.frombuffer(json.dumps(dict(metadata(), format_version=1)).encode(), np.uint8)
    extra = dict(arrays, extra=np.zeros(64 * 1024 * 1024 // 8))  # 64 MB that compresses to almost nothing
    np.savez_compressed(tmp_path / "extra.npz", **extra)
    del extra
    tracemalloc.start()
    with pytest.raises(W.WeightsError, match=r"extra\.npz: unexpected member 'extra'"):
        W.load(tmp_path / "extra.npz")  # refused by its name in the zip directory, never read
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 16 * 1024 * 1024, peak
    big = dict(arrays)
    big["stepper.W1"] = np.zeros((4096, 4096), np.float32)  # 64 MB where 8 x 8 floats are expected
    np.savez_compressed(tmp_path / "big.npz", **big)
    tracemalloc.start()
    with pytest.raises(W.WeightsError, match=r"member stepper\.W1 declares 67108992 bytes, more than"):
        W.load(tmp_path / "big.npz")
    peak = tracemalloc.get_traced_memory()[1]
    tracemalloc.stop()
    assert peak < 16 * 1024 * 1024, peak


def test_lmm_networks_report_the_file_and_field(tmp_path):
    from lmm.learned import LMMNetworks

    p = _with_meta(tmp_path, lambda m: m.pop("n_bones"))
    with pytest.raises(W.WeightsError, match=f"{p}: metadata field 'n_bones'"):
        LMMNetworks.load(p)

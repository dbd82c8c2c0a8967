"""The motion search networks (lmm.motion_search.encoder), their training (lmm.offline.search_training)
and the search evaluation (lmm.offline.search_eval, `lmm-studio eval-search`)."""
import json
import zipfile

import numpy as np
import pytest

from lmm.motion_search import encoder as enc
from lmm.motion_search import windows as W
from lmm.offline import search_data as data

CONVS = [[16, 5, 2], [16, 3, 1]]


def _random_arrays(meta, seed=0):
    rng = np.random.default_rng(seed)
    arrays = {k: rng.normal(0, 0.3, s).astype(np.float32) for k, s in enc.expected_shapes(meta).items()}
    arrays["in_std"] = np.abs(arrays["in_std"]) + 0.5
    return arrays


def _write(path, kind="encoder", **changes):
    meta = {"kind": kind, "name": kind, "convs": CONVS, "fcs": [24, 8] if kind == "encoder" else [32, 3],
            "embed_fc": 2 if kind == "encoder" else 1, "l2_normalize": kind == "encoder",
            "labels": [] if kind == "encoder" else ["a", "b", "c"]}
    meta.update(changes)
    full = dict(meta, format_version=enc.FORMAT_VERSION, window_frames=W.WINDOW_FRAMES, frame_dim=W.FRAME_DIM)
    return enc.save(path, _random_arrays(full), meta)


def test_numpy_inference_equals_torch(tmp_path):
    torch = pytest.importorskip("torch")
    from lmm.offline.search_training import TorchConvNet

    rng = np.random.default_rng(3)
    mean, std = rng.normal(size=W.FRAME_DIM), rng.uniform(0.5, 2.0, W.FRAME_DIM)
    torch.manual_seed(0)
    nets = [TorchConvNet("encoder", [[32, 5, 2], [32, 5, 2], [48, 3, 1]], [40, 16], 2, True, mean, std),
            TorchConvNet("classifier", [[32, 5, 1], [48, 3, 2]], [64, 4], 1, False, mean, std, "abcd")]
    x = rng.normal(size=(37, W.WINDOW_FRAMES, W.FRAME_DIM)).astype(np.float32) * 2
    for net in nets:
        net.save(tmp_path / f"{net.kind}.npz", {"note": "test"})
        loaded = enc.load(tmp_path / f"{net.kind}.npz")
        with torch.no_grad():
            want = net.embed(torch.from_numpy(x)).numpy()
            want_logits = net.logits(torch.from_numpy(x)).numpy()
        got = loaded.embed(x, chunk=10)   # chunks do not change the result
        assert got.shape == want.shape == (37, loaded.dim)
        np.testing.assert_allclose(got, want, atol=1e-5, rtol=0)
        np.testing.assert_allclose(loaded.logits(x), want_logits, atol=1e-5, rtol=0)
        assert np.abs(want).max() > 1e-2  # not a vacuous comparison of zeros
    assert np.allclose(np.linalg.norm(enc.load(tmp_path / "encoder.npz").embed(x), axis=1), 1.0, atol=1e-5)


def _zip_with(path, members: dict):
    with zipfile.ZipFile(path, "w") as z:
        for name, data_bytes in members.items():
            z.writestr(name, data_bytes)


def test_loader_refuses_bad_files(tmp_path):
    good = _write(tmp_path / "good.npz")
    net = enc.load(good)
    assert net.name.startswith("encoder-") and net.dim == 8
    cases = {}
    cases["missing.npz"] = (None, "search network file not found")
    (tmp_path / "text.npz").write_text("hello")
    cases["text.npz"] = (None, "truncated or corrupt")
    (tmp_path / "cut.npz").write_bytes(good.read_bytes()[:300])
    cases["cut.npz"] = (None, "truncated or corrupt")
    with np.load(good) as z:
        arrays = {k: z[k] for k in z.files}

    def variant(name, **replace):
        a = dict(arrays)
        for k, v in replace.items():
            if v is None:
                a.pop(k)
            else:
                a[k] = v
        np.savez(tmp_path / name, **a)

    meta = json.loads(arrays["metadata"].tobytes())
    as_bytes = lambda m: np.frombuffer(json.dumps(m).encode(), np.uint8)  # noqa: E731
    variant("nometa.npz", metadata=None)
    cases["nometa.npz"] = (None, "no metadata record")
    variant("kind.npz", metadata=as_bytes(dict(meta, kind="robot")))
    cases["kind.npz"] = (None, "metadata field 'kind'")
    variant("dim.npz", metadata=as_bytes(dict(meta, frame_dim=12)))
    cases["dim.npz"] = (None, "metadata field 'frame_dim' is 12")
    variant("convs.npz", metadata=as_bytes(dict(meta, convs=[[16, 4, 1]])))
    cases["convs.npz"] = (None, "metadata field 'convs'")
    variant("embedfc.npz", metadata=as_bytes(dict(meta, embed_fc=3)))
    cases["embedfc.npz"] = (None, "metadata field 'embed_fc'")
    variant("json.npz", metadata=np.frombuffer(b"{not json", np.uint8))
    cases["json.npz"] = (None, "not valid JSON")
    variant("shape.npz", **{"fc1.weight": np.zeros((8, 23), np.float32)})
    cases["shape.npz"] = (None, r"fc1.weight has shape \(8, 23\), expected \(8, 24\)")
    variant("absent.npz", **{"conv1.bias": None})
    cases["absent.npz"] = (None, "missing array conv1.bias")
    nan = arrays["fc0.bias"].copy()
    nan[3] = np.nan
    variant("nan.npz", **{"fc0.bias": nan})
    cases["nan.npz"] = (None, "fc0.bias holds 1 NaN/inf")
    variant("huge.npz", **{"fc0.bias": np.full_like(nan, 1e6)})
    cases["huge.npz"] = (None, "fc0.bias holds values up to 1e\\+06")
    variant("std.npz", in_std=np.zeros(W.FRAME_DIM, np.float32))
    cases["std.npz"] = (None, "in_std has non-positive entries")
    variant("int.npz", **{"fc0.bias": np.zeros(24, np.int64)})
    cases["int.npz"] = (None, "fc0.bias has dtype int64")
    variant("extra.npz", surprise=np.array([object()], dtype=object))
    cases["extra.npz"] = (None, "unexpected member 'surprise'")
    with pytest.raises(enc.SearchWeightsError, match="labels"):
        _write(tmp_path / "c.npz", "classifier", labels=["a", "b"])
    for name, (_, message) in cases.items():
        with pytest.raises(enc.SearchWeightsError, match=f"{name}: .*{message}"):
            enc.load(tmp_path / name)


def test_shipped_networks_load_and_embed():
    e = enc.load_default()
    assert e is not None and e.kind == "encoder" and e.dim == 64
    c = enc.load(enc.CLASSIFIER_WEIGHTS)
    assert c.kind == "classifier" and c.dim == 512 and len(c.labels) == 8
    x = np.random.default_rng(0).normal(size=(3, W.WINDOW_FRAMES, W.FRAME_DIM)).astype(np.float32)
    np.testing.assert_allclose(np.linalg.norm(e.embed(x), axis=1), 1.0, atol=1e-5)
    assert e.metadata["training"]["held_out_fraction"] == data.HELD_OUT_FRACTION


def test_labels_and_warped_segments():
    assert data.action_label("fallAndGetUp2_subject3.bvh") == "fallAndGetUp"
    assert data.action_label("sub/pushAndFall1_subject4.bvh.gz") == "pushAndFall"
    assert data.action_label("walk4_subject1.bvh") == "walk"
    f = np.random.default_rng(1).normal(size=(100, W.FRAME_DIM)).astype(np.float32)
    np.testing.assert_allclose(data.warped_segments(f, [10], [1.0])[0], f[10:10 + W.WINDOW_FRAMES])
    fast = data.warped_segments(f, [4], [2.0])[0]
    np.testing.assert_allclose(fast[:, :-3], f[4:4 + 2 * W.WINDOW_FRAMES:2, :-3], rtol=1e-6)
    np.testing.assert_allclose(fast[:, -3:], 2.0 * f[4:4 + 2 * W.WINDOW_FRAMES:2, -3:], rtol=1e-6)
    half = data.warped_segments(f, [0], [0.5])[0]
    np.testing.assert_allclose(half[1, :-3], 0.5 * (f[0, :-3] + f[1, :-3]), rtol=1e-5, atol=1e-6)


@pytest.fixture(scope="module")
def tiny_folder(tmp_path_factory):
    """Three short takes with two labels, cut from the shipped LAFAN1 files."""
    from lmm.data import bvh
    src = enc.DEFAULT_WEIGHTS.parents[1] / "lafan1"
    a = bvh.load(src / "multipleActions1_subject1.bvh.gz")
    b = bvh.load(src / "obstacles3_subject3.bvh.gz")
    folder = tmp_path_factory.mktemp("takes")
    bvh.save(folder / "walk1_subject1.bvh", a.slice(0, 300))
    bvh.save(folder / "walk1_subject2.bvh", a.slice(1000, 1300))
    (folder / "sub").mkdir()
    bvh.save(folder / "sub" / "dance1_subject1.bvh", b.slice(200, 500))
    nets = tmp_path_factory.mktemp("nets")
    return folder, _write(nets / "e.npz"), _write(nets / "c.npz", "classifier")


def test_eval_on_a_tiny_folder_reports_every_method_and_key(tiny_folder, tmp_path, monkeypatch):
    from lmm.offline import search_eval as ev
    monkeypatch.setenv("LMM_STUDIO_CACHE", str(tmp_path / "cache"))
    folder, e, c = tiny_folder
    report = ev.evaluate(folder, e, c, ev.EvalSettings(queries_per_take=4, latency_queries=3))
    assert report["n_takes"] == 3 and report["labels"] == {"dance": 1, "walk": 2}
    # 300 file frames at 30.0003 fps count as 30 fps (within 1e-4: LAFAN1's rounded frame time), not resampled
    assert report["n_windows"] == 3 * (300 - W.WINDOW_FRAMES + 1)
    assert set(report["methods"]) == set(ev.METHODS)
    keys = {"precision@1", "precision@5", "precision@10", "precision@5_other_takes", "precision@5_by_label",
            "recall@5_warp0.8", "recall@5_warp1.25", "recall@5_mirror", "recall@5_plain", "latency_ms", "dim"}
    for name, r in report["methods"].items():
        assert keys <= set(r), name
        for k in keys - {"precision@5_by_label", "latency_ms", "dim"}:
            assert 0.0 <= r[k] <= 1.0, (name, k)
        assert set(r["precision@5_by_label"]) == {"walk", "dance"}
    # the plain query is in the database: the features baseline finds it exactly
    assert report["methods"]["features"]["recall@5_plain"] == 1.0
    again = ev.evaluate(folder, e, c, ev.EvalSettings(queries_per_take=4, latency_queries=3))
    assert again["methods"]["encoder"]["database_embed_s"] == "cached"
    assert again["methods"]["encoder"]["precision@5"] == report["methods"]["encoder"]["precision@5"]


def test_eval_search_cli(tiny_folder, tmp_path, monkeypatch, capsys):
    from app.cli import main
    monkeypatch.setenv("LMM_STUDIO_CACHE", str(tmp_path / "cache"))
    folder, e, c = tiny_folder
    out = tmp_path / "r.json"
    assert main(["eval-search", "--data", str(folder), "--encoder", str(e), "--classifier", str(c),
                 "--queries-per-take", "3", "--json", str(out)]) == 0
    report = json.loads(out.read_text())
    assert set(report["methods"]) == {"encoder", "classifier", "features"}
    assert "| encoder |" in capsys.readouterr().out
    (tmp_path / "empty").mkdir()
    assert main(["eval-search", "--data", str(tmp_path / "empty"), "--encoder", str(e), "--classifier", str(c)]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "empty: no .bvh or .bvh.gz files" in err[0]
    assert main(["eval-search", "--data", str(folder), "--encoder", str(tmp_path / "none.npz"),
                 "--classifier", str(c)]) == 1
    assert "none.npz: search network file not found" in capsys.readouterr().err


def test_contrastive_losses():
    torch = pytest.importorskip("torch")
    from lmm.offline.search_training import nt_xent, sup_con

    torch.manual_seed(0)
    z = torch.nn.functional.normalize(torch.randn(8, 5), dim=1)
    # each view's only positive is its twin: supervised contrastive is NT-Xent
    assert torch.allclose(sup_con(z, torch.tensor([0, 1, 2, 3] * 2), 0.1), nt_xent(z[:4], z[4:], 0.1))
    # twins that are the same vector and far from the rest: a small loss; swapped twins: a large one
    a = torch.eye(5)[:4]
    assert nt_xent(a, a, 0.1) < 0.01 < 5 < nt_xent(a, a[[1, 0, 3, 2]], 0.1)


def test_shipped_encoder_finds_a_time_warped_noisy_window_at_its_source():
    from lmm.data import bvh
    from lmm.motion_search.embed import knn

    path = enc.DEFAULT_WEIGHTS.parents[1] / "lafan1" / "obstacles3_subject3.bvh.gz"
    frames = W.take_frames(bvh.load(path), str(path)).frames[:3000]
    e = enc.load_default()
    db = e.embed(W.windows(frames))
    rng = np.random.default_rng(7)
    starts = np.array([150, 700, 1333, 2100, 2800])
    q = data.warped_segments(frames, starts, np.full(len(starts), 1.2))
    q += rng.normal(0.0, 0.02, q.shape).astype(np.float32) * frames.std(axis=0)
    top, _ = knn(db, e.embed(q), 5)
    assert np.all(np.any(np.abs(top - starts[:, None]) <= 15, axis=1)), top
    # harder, and what the training taught it (an untrained network of the same shape and the features
    # baseline both find 0.2 of these): mirrored, 1.3x faster, more noise
    starts = np.arange(100, 2900, 140)
    q = W.mirror_frames(data.warped_segments(frames, starts, np.full(len(starts), 1.3)))
    q += rng.normal(0.0, 0.03, q.shape).astype(np.float32) * frames.std(axis=0)
    top, _ = knn(db, e.embed(q), 5)
    assert np.mean(np.any(np.abs(top - starts[:, None]) <= 15, axis=1)) >= 0.8

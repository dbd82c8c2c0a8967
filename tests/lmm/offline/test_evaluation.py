"""The learned-motion-matching metrics: projector metrics against projectors whose answers are known,
and `lmm-studio eval` end to end on the shipped networks."""
import dataclasses
import json

import numpy as np
import pytest

from lmm.data.build import load_or_build
from lmm.offline.evaluation import nearest, projector_metrics
from lmm.features import build_features
from lmm.learned import DEFAULT_WEIGHTS, LMMNetworks
from lmm.data.weights import WeightsError


@pytest.fixture(scope="module")
def setup():
    db, _ = load_or_build()
    features = build_features(db)
    try:
        nets = LMMNetworks.load(DEFAULT_WEIGHTS, db, features)
    except WeightsError as e:
        pytest.skip(f"shipped networks do not fit this database: {e}")
    X = nets.to_network_space(features.raw)
    rng = np.random.default_rng(0)
    Z = rng.normal(size=(X.shape[0], nets.n_latent)).astype(np.float32)
    return db, features, nets, X, Z


def with_projector(nets, fn):
    return dataclasses.replace(nets, projector=fn)


def test_oracle_projector_scores_perfectly(setup):
    """Returning the true nearest frame's features and latent: agreement 1, cost ratio 1, no error."""
    _, features, nets, X, Z = setup

    def oracle(q):
        idx, _ = nearest(q, X)
        return np.concatenate([X[idx], Z[idx]], axis=1)

    m = projector_metrics(with_projector(nets, oracle), features, n_queries=300, Z=Z)
    assert m["nn_agreement"] == 1.0 and m["nn_within_3_frames"] == 1.0
    assert m["cost_ratio_median"] == pytest.approx(1.0, abs=1e-4)
    assert m["feature_error_mean_abs"] < 1e-6 and m["projection_to_nn_median"] < 1e-5
    assert m["latent_error_mean_abs_std"] < 1e-6
    assert m["query_to_nn_median"] > 0.1


def test_identity_projector_agrees_but_the_distances_expose_it(setup):
    """The query itself has the query's nearest frame, so agreement alone cannot tell a projector that
    does nothing; the cost ratio (~0) and the projection's distance to the frame (= the query's) do."""
    _, features, nets, X, Z = setup
    identity = lambda q: np.concatenate([q, np.zeros((q.shape[0], nets.n_latent), np.float32)], axis=1)  # noqa: E731
    m = projector_metrics(with_projector(nets, identity), features, n_queries=300, Z=Z)
    assert m["nn_agreement"] == 1.0
    assert m["cost_ratio_median"] < 1e-6
    assert m["projection_to_nn_median"] == pytest.approx(m["query_to_nn_median"], rel=1e-5)


def test_wrong_projector_disagrees(setup):
    """A projector that answers a frame far along the database never agrees."""
    _, features, nets, X, Z = setup

    def shifted(q):
        idx, _ = nearest(q, X)
        far = (idx + X.shape[0] // 2) % X.shape[0]
        return np.concatenate([X[far], Z[far]], axis=1)

    m = projector_metrics(with_projector(nets, shifted), features, n_queries=300, Z=Z)
    assert m["nn_agreement"] < 0.02
    assert m["cost_ratio_median"] > 2.0
    assert m["latent_error_mean_abs_std"] > 0.5


def test_eval_command_writes_every_metric_and_plot(setup, tmp_path):
    from app.cli import main
    out = tmp_path / "e.json"
    assert main(["eval", "--json", str(out), "--seconds", "3", "--queries", "256"]) == 0
    m = json.loads(out.read_text())
    for key in ("mean_joint_error_cm",):
        assert np.isfinite(m["decompressor"][key])
    for key in ("nn_agreement", "cost_ratio_median", "nn_agreement_runtime", "latent_error_mean_abs_std",
                "query_to_nn_median", "projection_to_nn_median"):
        assert np.isfinite(m["projector"][key]), key
    assert np.isfinite(m["stepper"]["drift_60"])
    assert np.isfinite(m["mm_vs_lmm"]["mean_joint_distance_cm"])
    assert set(m["foot_skating"]) == {"mm_cm_s", "lmm_cm_s"}
    for name in ("mm", "lmm"):                    # the motion quality, as run --metrics-json has it
        q = m["quality"][name]
        assert q["pops_per_min"] >= 0 and q["knee_snaps_per_min"] >= 0 and q["jerk_p99_ratio"] > 0, q
    assert m["quality"]["database"]["max_acceleration"] > 0
    assert m["lmm_run"]["finite"]
    for name in ("training_losses.png", "latent_traces.png", "per_joint_error.png"):
        png = tmp_path / name
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n", name


def test_eval_names_a_broken_weights_file(setup, tmp_path, capsys):
    from app.cli import main
    bad = tmp_path / "default.npz"
    bad.write_bytes(DEFAULT_WEIGHTS.read_bytes()[:1000])
    assert main(["eval", "--weights", str(bad)]) == 1
    err = capsys.readouterr().err
    assert str(bad) in err and "Traceback" not in err

"""Input derived from a take's root motion (lmm.input_from_motion, ``lmm-studio input-from``)."""
import subprocess
import sys

import numpy as np
import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data import bvh
from lmm.data.manifest import load_manifest
from lmm.input_from_motion import derive_input, replay, take_root_path, write_input_csv


@pytest.fixture(scope="module")
def take():
    m = load_manifest(DEFAULT_MANIFEST)
    clip = m.clips[0]
    return m, clip.file, bvh.load(clip.file)


@pytest.fixture(scope="module")
def derived(take):
    m, path, anim = take
    return derive_input(take_root_path(anim, m, str(path), (200, 200 + 30 * 40)))


def test_the_replayed_input_follows_the_take(derived):
    e = derived.path_error()
    assert e["ticks"] == len(derived.inputs) and abs(e["seconds"] - 40.0) < 0.1
    # a 40 s stretch of walking and running: the simulation object stays within centimetres of the take
    assert e["position_mean_m"] < 0.03 and e["position_max_m"] < 0.15, e
    assert e["yaw_mean_deg"] < 15.0, e
    # the path is not trivially still: it travels (about 12 m, back and forth)
    assert np.linalg.norm(np.diff(derived.reference_positions, axis=0), axis=1).sum() > 8.0
    # and the input is not a constant: it steers
    assert len({(round(i.left_x, 2), round(i.left_y, 2)) for i in derived.inputs}) > 50


def test_the_written_log_replays_bit_exact(derived, tmp_path):
    from lmm.data.inputs import load_input_csv
    out = tmp_path / "in.csv"
    write_input_csv(derived, out)
    log = load_input_csv(out)
    inputs = [log(t) for t in derived.times]
    pos, yaw = replay(inputs)
    np.testing.assert_array_equal(pos, derived.replay_positions)


def test_a_controller_follows_the_same_simulation_object(derived):
    from lmm.data.build import load_or_build
    from lmm.factory import make_controller
    from lmm.features import build_features
    db, _ = load_or_build(None)
    c = make_controller("mm", db, build_features(db))
    c.reset()
    for i, inp in enumerate(derived.inputs[:240]):
        _, snap = c.step(inp, derived.dt)
        np.testing.assert_allclose(snap.simulation_position, derived.replay_positions[i], atol=1e-9)


def test_bad_ranges_and_skeletons_are_one_line(take, tmp_path):
    m, path, anim = take
    from lmm.errors import InputError
    for frames in ((5, 5), (0, anim.n_frames + 1), (-3, 10)):
        with pytest.raises(InputError, match="frames"):
            take_root_path(anim, m, str(path), frames)
    text = path.read_text() if path.suffix == ".bvh" else None
    if text is None:
        import gzip
        text = gzip.decompress(path.read_bytes()).decode()
    odd = tmp_path / "odd.bvh"
    odd.write_text(text.replace("Spine", "Torso"))
    r = subprocess.run([sys.executable, "-m", "app.cli", "input-from", str(odd), "--out", str(tmp_path / "x.csv")],
                       capture_output=True, text=True)
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 1 and len(lines) == 1 and "odd.bvh" in lines[0] and "Spine" in lines[0], r.stderr
    assert not (tmp_path / "x.csv").exists()

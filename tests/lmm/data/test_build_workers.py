"""Building takes in worker processes gives the same database, bit for bit, and the same errors; forward
kinematics of a few bones equals the same columns of the whole skeleton's."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest

from lmm import DATA_DIR
from lmm.data.build import build
from lmm.data.manifest import ManifestError, load_manifest
from lmm.errors import InputError

TAKES = DATA_DIR / "lafan1"


def _manifest(tmp_path, clips, **settings):
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"name": "workers", "clips": clips, **settings}))
    return load_manifest(path)


CLIPS = [
    {"file": str(TAKES / "obstacles3_subject4.bvh.gz"), "ranges": [[100, 400], [500, 620]]},
    {"file": str(TAKES / "multipleActions1_subject2.bvh.gz"), "ranges": [[40, 260]]},
    {"file": str(TAKES / "obstacles3_subject3.bvh.gz"), "ranges": [[0, 180]]},
]


def test_workers_build_the_same_database(tmp_path):
    m = _manifest(tmp_path, CLIPS)
    labels = []
    one, one_meta = build(m, workers=0).to_archive()
    two, two_meta = build(m, workers=2,
                          progress=lambda done, total, label: labels.append((done, total, label))).to_archive()
    assert one_meta == two_meta and set(one) == set(two)
    for name in one:
        assert one[name].dtype == two[name].dtype, name
        assert np.array_equal(one[name], two[name]), name
    assert [d for d, _, _ in labels] == list(range(1, 9)) and {t for _, t, _ in labels} == {8}
    assert labels[-1][2] == "obstacles3_subject3[0:180] mirrored"


@pytest.mark.parametrize("bad_clip, field", [
    ({"file": str(TAKES / "obstacles3_subject3.bvh.gz"), "ranges": [[0, 99999]]}, "clips[1].ranges[0]"),
    ({"file": "broken.bvh"}, "broken.bvh"),
])
def test_workers_raise_the_same_error(tmp_path, bad_clip, field):
    (tmp_path / "broken.bvh").write_text("HIERARCHY\nROOT Hips\n{\n")
    m = _manifest(tmp_path, [CLIPS[0], bad_clip, CLIPS[1]])
    messages = []
    for workers in (0, 2):
        with pytest.raises(InputError, match=field.replace("[", r"\[").replace("]", r"\]")) as e:
            build(m, workers=workers)
        messages.append(f"{type(e.value).__name__}: {e.value}")
    assert messages[0] == messages[1]


def test_workers_check_the_frame_limit_in_order(tmp_path, monkeypatch):
    import lmm.data.build as database_build

    monkeypatch.setattr(database_build, "MAX_DATABASE_FRAMES", 1700)  # clips[0] fills it, clips[1] passes it
    m = _manifest(tmp_path, CLIPS)
    messages = []
    for workers in (0, 2):
        with pytest.raises(ManifestError, match=r"clips\[1\]\.ranges\[0\].*would pass 1700 frames") as e:
            build(m, workers=workers)
        messages.append(str(e.value))
    assert messages[0] == messages[1]


def test_global_transforms_of_equals_the_whole_skeleton(db):
    frames = slice(1000, 1600)
    g_rot, g_pos = db.global_transforms(frames)
    bones = [db.bone("left_foot"), 0, db.bone("right_toe"), db.bone("hips")]
    rot, pos = db.global_transforms_of(bones, frames)
    assert rot.dtype == np.float64 and rot.shape == (600, 4, 4) and pos.shape == (600, 4, 3)
    assert np.array_equal(rot, g_rot[:, bones]) and np.array_equal(pos, g_pos[:, bones])


def test_build_db_refuses_jobs_below_one(tmp_path):
    r = subprocess.run([sys.executable, "-m", "app.cli", "build-db", "--jobs", "0", "--quiet"],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and r.stderr.strip() == "lmm-studio build-db: error: --jobs must be at least 1, got 0"


def test_features_do_not_depend_on_the_chunk_size(db, monkeypatch):
    import lmm.features as features
    from lmm.data.database import Database

    monkeypatch.setattr(features, "_CHUNK_FRAMES", 10**9)  # one pass over every frame, as before chunking
    monkeypatch.setattr(Database, "FK_CHUNK_FRAMES", 10**9)
    whole = features.compute_raw(db)
    monkeypatch.setattr(features, "_CHUNK_FRAMES", 777)
    monkeypatch.setattr(Database, "FK_CHUNK_FRAMES", 1000)
    chunked = features.compute_raw(db)
    assert whole.dtype == chunked.dtype == np.float32 and np.array_equal(whole, chunked)
    g_rot, g_pos = db.global_transforms()  # every bone: the feet's columns agree with the chain-only FK
    foot = db.bone("left_foot")
    from lmm import quat
    expected = quat.inv_mul_vec(g_rot[:, 0], g_pos[:, foot] - g_pos[:, 0]).astype(np.float32)
    first = features.layout_slices(features.DEFAULT_LAYOUT)[0]
    assert features.DEFAULT_LAYOUT[0].kind == "bone_position" and db.bone(features.DEFAULT_LAYOUT[0].bone) == foot
    assert np.array_equal(chunked[:, first], expected)


def _build_db(tmp_path, manifest, cache, *extra):
    import os

    env = dict(os.environ, LMM_STUDIO_CACHE=str(cache))
    return subprocess.run([sys.executable, "-m", "app.cli", "build-db", "--manifest", str(manifest), "--quiet", *extra],
                          capture_output=True, text=True, timeout=300, env=env)


def test_build_db_in_processes_writes_the_same_files_and_warnings(tmp_path):
    """With two jobs the derived arrays are computed in a second process while the database file is
    written, and the data checks in a third: the same files, bit for bit, and the same warnings as one
    process doing it all in turn."""
    _manifest(tmp_path, CLIPS)
    outputs = {}
    for jobs in ("1", "2"):
        cache = tmp_path / f"cache{jobs}"
        r = _build_db(tmp_path, tmp_path / "m.json", cache, "--jobs", jobs)
        assert r.returncode == 0, r.stderr
        (db_file,) = cache.glob("*.npz")
        derived = {p.name: p.read_bytes() for p in (cache / (db_file.name + ".derived")).glob("*.npy")}
        warnings = [line for line in r.stderr.splitlines() if line.strip()]
        outputs[jobs] = (db_file.name, db_file.read_bytes(), derived, warnings)
    assert {n.split("-")[0] for n in outputs["2"][2]} == {"features", "root_local_velocities",
                                                         "range_contact_heights", "default_start_frame",
                                                         "source_ground_skating"}
    assert outputs["1"] == outputs["2"]
    assert outputs["2"][3] and all(line.startswith("warning: ") for line in outputs["2"][3])


def test_build_db_that_cannot_write_its_file_leaves_nothing_beside_it(tmp_path):
    """The database file cannot be written (a file where its folder should be): one line, no warnings
    of the checks that ran meanwhile, no derived-array folder."""
    blocker = tmp_path / "file.txt"
    blocker.write_text("a file, not a folder")
    _manifest(tmp_path, CLIPS[:2])
    r = _build_db(tmp_path, tmp_path / "m.json", tmp_path / "cache", "--jobs", "2", "--out", str(blocker / "db.npz"))
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert r.returncode == 1 and len(lines) == 1 and "db.npz" in lines[0] and "Traceback" not in r.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt", "m.json"]

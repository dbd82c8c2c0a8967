"""Database build invariants, cache behaviour and manifest errors."""
from __future__ import annotations

import json
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from lmm import DEFAULT_MANIFEST, quat
from lmm.data import bvh
from lmm.data.build import build, load_or_build
from lmm.data.cache import manifest_key
from lmm.data.database import Database, DatabaseError
from lmm.data.preparation import mirror_local, mirror_map
from lmm.filters import median_filter
from lmm.data.manifest import ManifestError, load_manifest

DATA = DEFAULT_MANIFEST.parent


@pytest.fixture(scope="module")
def default_db(tmp_path_factory):
    return load_or_build(cache_dir=tmp_path_factory.mktemp("dbcache"))[0]


@pytest.fixture(scope="module")
def default_manifest():
    return load_manifest(DEFAULT_MANIFEST)


def small_manifest(tmp_path: Path, name: str = "manifest.json", **overrides) -> Path:
    data = {
        "name": "small",
        "clips": [{"file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"), "ranges": [[100, 400], [500, 620]]}],
    }
    data.update(overrides)
    path = tmp_path / name
    path.write_text(json.dumps(data))
    return path


# ---------------------------------------------------------------------------------------------
# the shipped default
# ---------------------------------------------------------------------------------------------

def test_default_has_enough_locomotion(default_db, default_manifest):
    source_frames = sum(b - a for c in default_manifest.clips for a, b in c.ranges)
    assert source_frames / 30.0 >= 180.0, "at least 3 minutes of locomotion before mirroring"
    assert default_db.n_frames > 2 * 60 * 180 * 0.99
    assert default_db.names[0] == "Simulation" and default_db.parents[0] == -1
    assert default_db.n_bones == 23
    assert default_db.range_mirrored.sum() == default_db.n_ranges // 2
    for name in ("positions", "rotations", "velocities", "angular_velocities"):
        assert np.all(np.isfinite(getattr(default_db, name))), name


def test_simulation_bone_faces_the_direction_of_travel(default_db):
    sim_rot = default_db.rotations[:, 0].astype(np.float64)
    sim_vel = default_db.velocities[:, 0].astype(np.float64)
    speed = np.linalg.norm(sim_vel, axis=-1)
    moving = speed > 1.0
    forward = quat.mul_vec(sim_rot[moving], np.array([0.0, 0.0, 1.0]))
    cos = np.sum(forward * sim_vel[moving], axis=-1) / speed[moving]
    assert np.median(cos) > 0.9
    assert np.allclose(default_db.positions[:, 0, 1], 0.0)  # on the ground


def test_mirrored_ranges_mirror_the_originals(default_db):
    # range 1 is the mirror of range 0: negated X of the simulation bone path (up to the smoothing start)
    a = slice(default_db.range_starts[0], default_db.range_stops[0])
    b = slice(default_db.range_starts[1], default_db.range_stops[1])
    assert default_db.range_mirrored[1] and not default_db.range_mirrored[0]
    pa, pb = default_db.positions[a, 0], default_db.positions[b, 0]
    assert np.allclose(pa[:, 0], -pb[:, 0], atol=1e-4)
    assert np.allclose(pa[:, 2], pb[:, 2], atol=1e-4)


def test_mirroring_twice_gives_back_the_original():
    anim = bvh.load(DATA / "lafan1" / "multipleActions1_subject1.bvh.gz")
    rot = quat.unroll(anim.local_rotations()[2000:2300])
    pos = anim.local_positions()[2000:2300] * 0.01
    idx = mirror_map(anim.names, [("Left", "Right")])
    assert anim.names[idx[anim.names.index("LeftFoot")]] == "RightFoot"
    assert idx[anim.names.index("Spine")] == anim.names.index("Spine")
    once_rot, once_pos = mirror_local(rot, pos, anim.parents, idx)
    assert not np.allclose(once_pos, pos, atol=1e-3)  # it did change something
    twice_rot, twice_pos = mirror_local(once_rot, once_pos, anim.parents, idx)
    assert np.abs(twice_pos - pos).max() < 1e-5
    dot = np.abs(np.sum(twice_rot * rot, axis=-1))
    assert np.all(dot > 1.0 - 1e-10)  # same rotation up to sign: angle error < ~1e-5 rad


def test_contacts_are_exactly_the_filtered_toe_speed_under_threshold(default_db, default_manifest):
    threshold = np.float32(default_manifest.contact_speed_threshold_m_s)
    assert np.array_equal(default_db.contacts, default_db.toe_speeds < threshold)
    assert 0.2 < default_db.contacts.mean() < 0.8
    # and the stored speeds are the median-filtered toe speeds recomputed independently from the poses
    toes = [default_db.bone("left_toe"), default_db.bone("right_toe")]
    for r in range(0, default_db.n_ranges, 5):
        s, e = default_db.range_starts[r], default_db.range_stops[r]
        _, g_pos = default_db.global_transforms(slice(s, e))
        for k, t in enumerate(toes):
            p = g_pos[:, t]
            vel = np.empty_like(p)
            vel[1:-1] = (p[2:] - p[:-2]) * default_db.fps / 2
            vel[0] = (p[1] - p[0]) * default_db.fps
            vel[-1] = (p[-1] - p[-2]) * default_db.fps
            speed = median_filter(np.linalg.norm(vel, axis=-1), default_manifest.contact_median_window)
            assert np.abs(speed - default_db.toe_speeds[s:e, k]).max() < 2e-3
            agree = (speed < threshold) == default_db.contacts[s:e, k]
            assert agree.mean() > 0.995


def test_velocities_match_finite_differences(default_db):
    fps = default_db.fps
    for r in range(default_db.n_ranges):
        s, e = default_db.range_starts[r], default_db.range_stops[r]
        pos = default_db.positions[s:e].astype(np.float64)
        rot = default_db.rotations[s:e].astype(np.float64)
        fd = (pos[2:] - pos[:-2]) * fps / 2
        assert np.abs(fd - default_db.velocities[s + 1:e - 1]).max() < 1e-3
        ang = quat.to_scaled_angle_axis(quat.abs_(quat.mul_inv(rot[2:], rot[:-2]))) * fps / 2
        assert np.abs(ang - default_db.angular_velocities[s + 1:e - 1]).max() < 1e-2


def test_rotations_are_unit_and_continuous(default_db):
    rot = default_db.rotations.astype(np.float64)
    assert np.abs(np.linalg.norm(rot, axis=-1) - 1).max() < 1e-5
    for r in range(default_db.n_ranges):
        s, e = default_db.range_starts[r], default_db.range_stops[r]
        assert np.all(np.sum(rot[s + 1:e] * rot[s:e - 1], axis=-1) > 0)  # unrolled: no sign flips


def test_no_future_sample_crosses_its_range(default_db):
    frames = np.arange(default_db.n_frames)
    ranges = default_db.range_index(frames)
    for offset in (1, 20, 40, 60, 500):
        fut = default_db.future_frame(frames, offset)
        assert np.array_equal(default_db.range_index(fut), ranges)
        assert np.all(fut >= frames) and np.all(fut <= frames + offset)
        stops = default_db.range_stops[ranges]
        inside = frames + offset < stops
        assert np.array_equal(fut[inside], frames[inside] + offset)
        assert np.all(fut[~inside] == stops[~inside] - 1)


# ---------------------------------------------------------------------------------------------
# build settings, resampling, cache
# ---------------------------------------------------------------------------------------------

def test_resampling_to_60_hz_doubles_frames(tmp_path):
    db = build(load_manifest(small_manifest(tmp_path)))
    lengths = db.range_stops - db.range_starts
    assert list(lengths) == [599, 599, 239, 239]  # (n - 1) * 2 + 1 per range, mirrored copies after each
    db30 = build(load_manifest(small_manifest(tmp_path, target_fps=30, mirror=False)))
    assert list(db30.range_stops - db30.range_starts) == [300, 120]
    # the resampled motion passes through the original samples (every second frame)
    _, g60 = db.global_transforms(slice(0, 599))
    _, g30 = db30.global_transforms(slice(0, 300))
    assert np.abs(g60[::2, 1:] - g30[:, 1:]).max() < 0.02  # simulation smoothing differs slightly


def test_unit_scale_is_applied(tmp_path):
    db = build(load_manifest(small_manifest(tmp_path, mirror=False)))
    db_cm = build(load_manifest(small_manifest(tmp_path, mirror=False, unit_scale=1.0)))
    hips = db.bone("hips")
    ratio = np.linalg.norm(db_cm.positions[:, hips + 1]) / np.linalg.norm(db.positions[:, hips + 1])
    assert ratio == pytest.approx(100.0, rel=1e-3)


def test_cache_is_reused_and_keyed_by_settings(tmp_path):
    cache = tmp_path / "cache"
    m = small_manifest(tmp_path)
    db1, info1 = load_or_build(m, cache_dir=cache)
    db2, info2 = load_or_build(m, cache_dir=cache)
    assert not info1.cached and info2.cached and info1.path == info2.path
    assert np.array_equal(db1.positions, db2.positions) and db1.range_names == db2.range_names
    # a changed setting gives a different key and file
    m2 = small_manifest(tmp_path, "other.json", contacts={"speed_threshold_m_s": 0.3})
    db3, info3 = load_or_build(m2, cache_dir=cache)
    assert not info3.cached and db3.key != db1.key and info3.path != info1.path
    assert db3.contacts.mean() > db1.contacts.mean()
    # a damaged cache file is rebuilt, not trusted
    info1.path.write_bytes(b"PK\x03\x04 not really a zip")
    db4, info4 = load_or_build(m, cache_dir=cache)
    assert not info4.cached and np.array_equal(db4.positions, db1.positions)
    with np.load(info1.path, allow_pickle=False) as z:  # no pickled objects in the cache
        assert all(z[k].dtype != object for k in z.files)


def test_changed_file_contents_change_the_key(tmp_path):
    src = DATA / "lafan1" / "obstacles3_subject4.bvh.gz"
    copy = tmp_path / "take.bvh.gz"
    shutil.copy(src, copy)
    m = small_manifest(tmp_path, clips=[{"file": str(copy), "ranges": [[0, 100]]}])
    key1 = manifest_key(load_manifest(m))
    data = bytearray(copy.read_bytes())
    data[len(data) // 2] ^= 0xFF
    copy.write_bytes(bytes(data))
    assert manifest_key(load_manifest(m)) != key1


def test_database_load_rejects_garbage(tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"\x00" * 100)
    with pytest.raises(DatabaseError, match="bad.npz"):
        Database.load(bad)


# ---------------------------------------------------------------------------------------------
# manifest errors name the file and the field
# ---------------------------------------------------------------------------------------------

@pytest.mark.parametrize("overrides, field", [
    ({"clips": []}, "clips"),
    ({"clips": [{"file": "nope/missing.bvh"}]}, "clips[0].file"),
    ({"clips": [{"file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"), "ranges": [[10, 5]]}]}, "clips[0].ranges[0]"),
    ({"clips": [{"file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"), "ranges": [[0, "x"]]}]}, "clips[0].ranges[0]"),
    ({"unit_scale": -1}, "unit_scale"),
    ({"target_fps": "fast"}, "target_fps"),
    ({"mirror": "yes"}, "mirror"),
    ({"simulation": {"position_window": 30}}, "simulation.position_window"),
    ({"colour": "red"}, "colour"),
    ({"mirror_name_pairs": [["Left"]]}, "mirror_name_pairs"),
])
def test_manifest_errors(tmp_path, overrides, field):
    with pytest.raises(ManifestError) as err:
        load_manifest(small_manifest(tmp_path, **overrides))
    assert f"'{field}'" in str(err.value) and "manifest.json" in str(err.value)


def test_manifest_errors_found_during_build(tmp_path):
    past_end = small_manifest(tmp_path, clips=[{"file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"),
                                                "ranges": [[0, 99999]]}])
    with pytest.raises(ManifestError, match=r"clips\[0\]\.ranges\[0\].*past the last frame"):
        build(load_manifest(past_end))
    no_bone = small_manifest(tmp_path, bones={"left_toe": "LeftToeBase"})
    with pytest.raises(ManifestError, match="bones.left_toe"):
        build(load_manifest(no_bone))


def test_invalid_json_names_line(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{\n  "name": "x",\n  "clips": [\n}\n')
    with pytest.raises(ManifestError, match=r"broken.json.*line 4"):
        load_manifest(path)


def test_toml_manifest(tmp_path):
    path = tmp_path / "m.toml"
    path.write_text(f'name = "t"\nmirror = false\n[[clips]]\nfile = "{DATA / "lafan1" / "obstacles3_subject4.bvh.gz"}"\n'
                    'ranges = [[0, 50]]\n')
    m = load_manifest(path)
    assert m.name == "t" and not m.mirror and m.clips[0].ranges == [(0, 50)]


def test_build_db_cli(tmp_path):
    out = tmp_path / "db.npz"
    r = subprocess.run([sys.executable, "-m", "app.cli", "build-db", "--manifest", str(small_manifest(tmp_path)),
                        "--out", str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    for word in ("clips", "frames", "seconds", "bytes"):
        assert word in r.stdout
    assert out.is_file() and Database.load(out).n_frames == 599 * 2 + 239 * 2
    bad = tmp_path / "bad.json"
    bad.write_text('{"clips": [{"file": "missing.bvh"}]}')
    r = subprocess.run([sys.executable, "-m", "app.cli", "build-db", "--manifest", str(bad)],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "bad.json" in r.stderr and "Traceback" not in r.stderr


def test_broken_bvh_in_manifest_is_reported(tmp_path):
    broken = tmp_path / "broken.bvh"
    broken.write_text("HIERARCHY\nROOT Hips\n{\n  OFFSET 0 0 0\n  CHANNELS 3 Xrotation\n}\n")
    m = small_manifest(tmp_path, clips=[{"file": str(broken)}])
    r = subprocess.run([sys.executable, "-m", "app.cli", "build-db", "--manifest", str(m), "--out",
                        str(tmp_path / "o.npz")], capture_output=True, text=True, timeout=60)
    assert r.returncode == 1 and "broken.bvh" in r.stderr and "Traceback" not in r.stderr


def test_cache_from_other_build_code_is_rebuilt(tmp_path, monkeypatch):
    """A cache written by different build code is not served, even under the same key."""
    import lmm.data.build as database_build
    from lmm.data.cache import build_code_fingerprint

    cache = tmp_path / "cache"
    m = small_manifest(tmp_path)
    db1, info1 = load_or_build(m, cache_dir=cache)
    assert db1.build_fingerprint == build_code_fingerprint()
    assert load_or_build(m, cache_dir=cache)[1].cached
    monkeypatch.setattr(database_build, "build_code_fingerprint", lambda: "edited build code")
    db2, info2 = load_or_build(m, cache_dir=cache)
    assert not info2.cached and db2.key == db1.key and info2.path == info1.path


def test_tags_give_per_frame_masks_kept_in_the_cache_and_outside_the_key(tmp_path):
    def manifest(tags):
        return small_manifest(tmp_path, clips=[{
            "file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"), "tags": ["s4"],
            "ranges": [{"range": [100, 400], "tags": tags}, [500, 620]]}])

    cache = tmp_path / "cache"
    db, info = load_or_build(manifest(["walk"]), cache_dir=cache)
    assert not info.cached and db.tag_names == ["s4", "walk"]
    assert db.range_tags == [("s4", "walk"), ("s4", "walk"), ("s4",), ("s4",)]   # mirrored copies too
    walk = db.tag_mask("walk")
    assert walk.sum() == db.range_stops[1] and not walk[db.range_starts[2]:].any()
    assert db.tag_mask(["s4"]).all() and not db.tag_mask("nothing").any()
    assert db.tags_of(int(db.range_starts[2])) == ("s4",)
    again, info = load_or_build(manifest(["walk"]), cache_dir=cache)
    assert info.cached and np.array_equal(again.frame_tags, db.frame_tags) and again.tag_names == db.tag_names
    retagged, info = load_or_build(manifest(["run", "turn"]), cache_dir=cache)
    assert info.cached and retagged.key == db.key      # tags change no frame: same key, networks stay valid
    assert retagged.tag_names == ["run", "s4", "turn"] and retagged.tag_mask("run").sum() == walk.sum()


# ---------------------------------------------------------------------------------------------
# bounded builds, cache names from the hash only, outputs that cannot be written
# ---------------------------------------------------------------------------------------------

def test_cache_file_name_is_the_hash_only(tmp_path):
    import re

    cache = tmp_path / "cache"
    m = small_manifest(tmp_path)
    m.write_text(m.read_text().replace('"name": "small"', '"name": "walks \\u00fc (v2) .."'))
    db, info = load_or_build(m, cache_dir=cache)
    assert info.path.parent == cache and re.fullmatch(r"db-[0-9a-f]{32}\.npz", info.path.name)
    assert db.name == "walks ü (v2) .." and [p.name for p in cache.iterdir()] == [info.path.name]


def _take_with_frame_time(tmp_path: Path, frame_time: float) -> Path:
    anim = bvh.load(DATA / "lafan1" / "obstacles3_subject4.bvh.gz").slice(0, 200)
    anim.frame_time = frame_time
    path = tmp_path / f"take_{frame_time:g}.bvh"
    bvh.save(path, anim)
    return path


def test_frame_time_out_of_range_is_a_bvh_error_not_a_division_by_zero(tmp_path):
    take = _take_with_frame_time(tmp_path, 0.5)
    take.write_text(take.read_text().replace("Frame Time: 0.5", "Frame Time: 1000"))
    with pytest.raises(bvh.BVHError, match=r"take_0.5.bvh:\d+: expected a frame time from"):
        build(load_manifest(small_manifest(tmp_path, clips=[{"file": str(take)}])))


def test_a_range_resampled_below_four_frames_is_refused(tmp_path):
    take = _take_with_frame_time(tmp_path, 1e-4)  # 10 kHz: 100 frames are 10 ms, under one frame at 60 fps
    m = small_manifest(tmp_path, clips=[{"file": str(take), "ranges": [[0, 100]]}])
    with pytest.raises(ManifestError, match=r"clips\[0\]\.ranges\[0\].*make 1 at target_fps 60.*at least 4"):
        build(load_manifest(m))


def test_database_frame_limit_stops_the_build_before_resampling(tmp_path, monkeypatch):
    import lmm.data.build as database_build

    calls = []
    real = database_build.resample
    monkeypatch.setattr(database_build, "resample", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(database_build, "MAX_DATABASE_FRAMES", 1500)  # the first range: 599 x 2 mirrored
    with pytest.raises(ManifestError, match=r"clips\[0\]\.ranges\[1\].*pass 1500 frames"):
        build(load_manifest(small_manifest(tmp_path, clips=[
            {"file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"), "ranges": [[100, 400], [500, 620]]}])))
    assert len(calls) == 1  # the second range was refused before it was resampled


def test_unwritable_out_is_an_oserror_and_unwritable_cache_is_reported(tmp_path, monkeypatch):
    def refuse(self, path):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(Database, "save", refuse)
    m = small_manifest(tmp_path, clips=[{"file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"),
                                         "ranges": [[0, 50]]}])
    with pytest.raises(PermissionError):
        load_or_build(m, out_path=tmp_path / "ro" / "db.npz")
    db, info = load_or_build(m, cache_dir=tmp_path / "cache")
    assert info.path is None and "cannot write the cache" in info.not_saved and db.n_frames > 0


def test_unreadable_take_is_a_manifest_error(tmp_path, monkeypatch):
    import lmm.data.cache as cache
    from lmm.data.cache import manifest_key

    def refuse(path):
        raise PermissionError(13, "Permission denied", str(path))

    monkeypatch.setattr(cache, "_file_digest", refuse)
    with pytest.raises(ManifestError, match=r"clips\[0\]\.file.*Permission denied"):
        manifest_key(load_manifest(small_manifest(tmp_path)))


def test_build_db_out_into_a_folder_it_cannot_write(tmp_path):
    blocker = tmp_path / "file.txt"
    blocker.write_text("a file, not a folder")
    out = blocker / "db.npz"
    m = small_manifest(tmp_path, clips=[{"file": str(DATA / "lafan1" / "obstacles3_subject4.bvh.gz"),
                                         "ranges": [[0, 50]]}])
    r = subprocess.run([sys.executable, "-m", "app.cli", "build-db", "--manifest", str(m), "--out", str(out),
                        "--quiet", "--no-checks"], capture_output=True, text=True, timeout=120)
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert r.returncode == 1 and len(lines) == 1 and "db.npz" in lines[0] and "Traceback" not in r.stderr
    assert "file " not in r.stdout and not out.exists()


def test_build_db_refuses_a_bad_manifest_field_in_one_line(tmp_path):
    m = small_manifest(tmp_path, target_fps=1e12)
    r = subprocess.run([sys.executable, "-m", "app.cli", "build-db", "--manifest", str(m), "--quiet"],
                       capture_output=True, text=True, timeout=60)
    lines = [line for line in r.stderr.splitlines() if line.strip()]
    assert r.returncode == 1 and len(lines) == 1 and "manifest.json" in lines[0] and "'target_fps'" in lines[0]

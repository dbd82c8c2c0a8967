"""Large databases: manifests with a configurable root, memory-mapped caches, cached derived arrays."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from lmm import DATA_DIR
from lmm.data.build import load_or_build
from lmm.data.database import MAPPED_ARRAYS, Database
from lmm.data.manifest import ManifestError, load_manifest
from lmm.data.npz_mmap import map_members


def _manifest(tmp_path, root: str) -> str:
    path = tmp_path / "m.json"
    path.write_text(json.dumps({"root": root, "clips": [{"file": "multipleActions1_subject1.bvh.gz",
                                                         "ranges": [[1130, 1200]]}]}))
    return str(path)


def test_root_takes_environment_variables(tmp_path, monkeypatch):
    monkeypatch.setenv("LMM_TEST_TAKES", str(DATA_DIR / "lafan1"))
    m = load_manifest(_manifest(tmp_path, "${LMM_TEST_TAKES}"))
    assert m.clips[0].file == (DATA_DIR / "lafan1" / "multipleActions1_subject1.bvh.gz").resolve()
    monkeypatch.delenv("LMM_TEST_TAKES")
    with pytest.raises(ManifestError, match="field 'root': environment variable LMM_TEST_TAKES is not set"):
        load_manifest(_manifest(tmp_path, "$LMM_TEST_TAKES"))
    with pytest.raises(ManifestError, match="field 'root': no such folder"):
        load_manifest(_manifest(tmp_path, "no-such-folder"))


def test_shipped_full_manifest_names_its_root(monkeypatch):
    monkeypatch.delenv("LAFAN1_DIR", raising=False)
    with pytest.raises(ManifestError, match="environment variable LAFAN1_DIR is not set"):
        load_manifest(DATA_DIR / "manifests" / "lafan1_full.json")


def test_full_manifest_tags_every_take_and_its_preset_names_only_those_tags(tmp_path, monkeypatch):
    """Each take of the full LAFAN1 manifest carries its action family as a tag, and the shipped locomotion
    preset is a valid tuning that excludes and biases only tags the manifest has (a misspelt one would do
    nothing)."""
    from lmm.tuning import Tuning

    path = DATA_DIR / "manifests" / "lafan1_full.json"
    files = [c["file"] for c in json.loads(path.read_text())["clips"]]
    for name in files:                       # the manifest's files, empty: only the manifest is read
        (tmp_path / name).touch()
    monkeypatch.setenv("LAFAN1_DIR", str(tmp_path))
    m = load_manifest(path)
    for clip in m.clips:
        family = re.match(r"[A-Za-z]+?(?=\d)", clip.source).group(0)
        assert clip.tags, clip.source
        assert {"pushAndFall": {"push", "fall"}, "fallAndGetUp": {"fall"}, "multipleActions": {"multiple-actions"}
                }.get(family, {family}) == set(clip.tags), clip.source
    preset = DATA_DIR / "manifests" / "lafan1_full_locomotion.tuning.json"
    tuning = Tuning.load(preset)
    named = Tuning.read_preset(preset)
    excluded = {t for t, on in named["tag_excluded"].items() if on}
    biased = {t for t, b in named.get("tag_bias", {}).items() if b}
    assert excluded == {"dance", "fall", "ground", "push"} and all(tuning.tag_excluded[t] for t in excluded)
    assert (excluded | biased) <= set(m.tag_names()) and all(tuning.tag_bias[t] > 0 for t in biased)
    assert not (excluded | biased) & {"walk", "multiple-actions"}   # the locomotion takes stay in


def test_mapped_database_equals_read_database(tmp_path, monkeypatch):
    monkeypatch.setenv("LMM_TEST_TAKES", str(DATA_DIR / "lafan1"))
    db, info = load_or_build(_manifest(tmp_path, "${LMM_TEST_TAKES}"), cache_dir=tmp_path / "cache")
    mapped = map_members(info.path, MAPPED_ARRAYS)
    assert {"positions", "rotations", "velocities", "angular_velocities"} <= set(mapped)
    assert all(isinstance(a, np.memmap) for a in mapped.values())
    read, lazy = Database.load(info.path, mmap=False), Database.load(info.path, mmap=True)
    for name in ("positions", "rotations", "velocities", "angular_velocities", "contacts", "toe_speeds"):
        assert np.array_equal(getattr(read, name), getattr(lazy, name)), name
        assert not getattr(lazy, name).flags.writeable


def test_derived_arrays_are_cached_bit_identical(tmp_path, monkeypatch):
    from lmm.source_pose import root_local_velocities
    from lmm.features import build_features

    monkeypatch.setenv("LMM_TEST_TAKES", str(DATA_DIR / "lafan1"))
    _, info = load_or_build(_manifest(tmp_path, "${LMM_TEST_TAKES}"), cache_dir=tmp_path / "cache")
    loaded = Database.load(info.path)
    computed = build_features(loaded).raw            # computed, then written beside the file
    assert list((info.path.parent / (info.path.name + ".derived")).glob("features-*.npy"))
    again = build_features(Database.load(info.path)).raw  # from the cache
    in_memory = Database.load(info.path, mmap=False)
    in_memory.source_path = None                     # no file: computed every time
    assert np.array_equal(computed, again) and np.array_equal(again, build_features(in_memory).raw)
    for a, b in zip(root_local_velocities(Database.load(info.path)), root_local_velocities(in_memory)):
        assert np.array_equal(a, b)


def test_compressor_latents_are_cached_bit_identical(tmp_path, monkeypatch):
    """The studio's table of every frame's compressor latent is worked out once per compressor file and
    read afterwards; another compressor file is worked out again; a broken one is a WeightsError naming
    the file, and nothing is stored for it."""
    import shutil

    import lmm.latents as latents
    from lmm.data.weights import WeightsError, load as load_weights, save as save_weights
    from lmm.features import build_features

    _, info = load_or_build(None)                    # the shipped database, from the suite's cache
    path = tmp_path / info.path.name
    shutil.copyfile(info.path, path)                 # its derived arrays go beside this copy
    db = Database.load(path)
    features = build_features(db)
    comp = DATA_DIR / "weights" / "compressor.npz"
    derived = tmp_path / (path.name + ".derived")
    computed = latents.cached_database_latents(comp, db, features)        # worked out, then stored
    assert computed.dtype == np.float32 and computed.shape == (db.n_frames, 32)
    assert len(list(derived.glob("compressor_latents-*.npy"))) == 1

    calls = []

    def spy(compressor, database, frames=None):
        calls.append(compressor)
        return np.full((database.n_frames, compressor.n_out), 7.0, np.float32)

    monkeypatch.setattr(latents, "database_latents", spy)
    again = latents.cached_database_latents(comp, Database.load(path), features)
    assert not calls and np.array_equal(again, computed)                   # read, the same bits

    wf = load_weights(comp)
    arrays = dict(wf.arrays)
    arrays["compressor.W0"] = arrays["compressor.W0"] * 2.0
    other = save_weights(tmp_path / "other" / "compressor.npz", arrays, wf.metadata)
    assert np.all(latents.cached_database_latents(other, db, features) == 7.0) and len(calls) == 1

    broken = tmp_path / "broken" / "compressor.npz"
    broken.parent.mkdir()
    broken.write_bytes(comp.read_bytes()[:5000])     # cut short
    for bad in (broken, tmp_path / "missing.npz"):
        with pytest.raises(WeightsError, match=re.escape(str(bad))):
            latents.cached_database_latents(bad, db, features)
    assert len(calls) == 1 and len(list(derived.glob("compressor_latents-*.npy"))) == 1


def test_small_caches_are_read_whole_and_large_ones_mapped(tmp_path, monkeypatch):
    """A small cache is read into memory (no page faults inside ticks); from MAP_MIN_BYTES up it is mapped."""
    import lmm.data.npz_mmap as npz_mmap

    monkeypatch.setenv("LMM_TEST_TAKES", str(DATA_DIR / "lafan1"))
    _, info = load_or_build(_manifest(tmp_path, "${LMM_TEST_TAKES}"), cache_dir=tmp_path / "cache")
    small = Database.load(info.path)
    assert not isinstance(small.positions.base, np.memmap)    # its own memory, read from the file
    monkeypatch.setattr(npz_mmap, "MAP_MIN_BYTES", 1)
    large = Database.load(info.path)
    assert isinstance(large.positions.base, np.memmap)         # a view of the file's map
    assert np.array_equal(small.positions, large.positions)

"""lmm.data.ranges: database ranges in the files' own frames."""
from __future__ import annotations

import json

import numpy as np
import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data import bvh
from lmm.data.build import build, load_or_build
from lmm.data.manifest import load_manifest
from lmm.data.ranges import (RangeSelectionError, check_selection, database_ranges, manifest_range,
                             range_of_frame)
from lmm.errors import InputError

TAKE = DEFAULT_MANIFEST.parent / "lafan1" / "obstacles3_subject4.bvh.gz"


def small(tmp_path, **settings):
    path = tmp_path / "m.json"
    data = {"name": "small", "clips": [{"file": str(TAKE), "ranges": [
        {"range": [100, 400], "tags": ["walk"]}, {"range": [500, 620], "tags": ["run", "turn"]}]}]}
    data.update(settings)
    path.write_text(json.dumps(data))
    m = load_manifest(path)
    return build(m), m


@pytest.fixture(scope="module")
def source():
    anim = bvh.load(TAKE)
    return anim.local_rotations()


def nearest_source_frames(db, rotations, frames, around, reach=12):
    """For each database frame, the source frame within ``reach`` of ``around`` whose local joint
    rotations are nearest (every joint but the file's root, which the build re-parents; the database's
    joint j + 1 is the file's joint j: bone 0 is the simulation bone)."""
    out = []
    for f, c in zip(frames, np.rint(around).astype(int)):
        lo = max(c - reach, 0)
        q = db.rotations[f, 2:].astype(np.float64)                       # (J-1, 4)
        src = rotations[lo:c + reach + 1, 1:]                            # (n, J-1, 4)
        d = (1.0 - np.abs(np.einsum("njk,jk->nj", src, q))).sum(axis=1)  # 0 for the same pose
        out.append(lo + int(d.argmin()))
    return np.array(out)


@pytest.mark.parametrize("settings, step", [({"target_fps": 60}, 0.5), ({"target_fps": 40}, 0.75),
                                            ({"target_fps": 60, "speed_scale": 1.3}, 0.65),
                                            ({"target_fps": 30}, 1.0)])
def test_database_frames_map_to_the_file_frames_they_were_resampled_at(tmp_path, source, settings, step):
    db, m = small(tmp_path, mirror=False, **settings)
    ranges = database_ranges(db, m)
    assert [r.step for r in ranges] == pytest.approx([step, step])
    for r in ranges:
        frames = np.arange(r.db_start, r.db_stop, 7)
        mapped = r.source_frame(frames)
        exact = r.source_start + (frames - r.db_start) * step
        assert np.abs(mapped - exact).max() <= 0.5 + 1e-9
        # the data agree: the source frame nearest in pose is the mapped one (within the resampling)
        nearest = nearest_source_frames(db, source, frames, exact)
        assert np.abs(nearest - exact).max() <= 1.0
        # and back: a file frame maps to the database frame resampled nearest to it
        assert r.db_frame(r.source_start) == r.db_start
        assert r.db_frame(r.source_stop - 1) == r.db_stop - 1
        assert r.source_frame(r.db_frame(mapped)).tolist() == mapped.tolist()


def test_files_tags_and_mirrors_as_the_manifest_gives_them(tmp_path):
    db, m = small(tmp_path)
    ranges = database_ranges(db, m)
    assert [(r.source_start, r.source_stop, r.mirrored, r.tags) for r in ranges] == [
        (100, 400, False, ("walk",)), (100, 400, True, ("walk",)),
        (500, 620, False, ("run", "turn")), (500, 620, True, ("run", "turn"))]
    assert {r.file for r in ranges} == {str(TAKE)}
    assert [r.seconds for r in ranges] == pytest.approx([599 / 60, 599 / 60, 239 / 60, 239 / 60])
    # without the manifest the file is the range's stem
    assert {r.file for r in database_ranges(db)} == {"obstacles3_subject4"}
    assert range_of_frame(ranges, 0).index == 0
    assert range_of_frame(ranges, 599).index == 1
    assert range_of_frame(ranges, db.n_frames - 1).index == 3
    assert range_of_frame(ranges, db.n_frames) is None and range_of_frame(ranges, -1) is None


def test_the_shipped_database_names_files_as_its_manifest_does():
    db, _ = load_or_build()
    m = load_manifest(DEFAULT_MANIFEST)
    ranges = database_ranges(db, m)
    assert len(ranges) == db.n_ranges
    written = {c.source for c in m.clips}
    assert {r.file for r in ranges} == written
    assert all(r.step == 0.5 for r in ranges)         # 30 fps takes in a 60 fps database
    first = m.clips[0].ranges[0]
    assert (ranges[0].source_start, ranges[0].source_stop) == tuple(first)


def test_manifest_range_and_bad_selections(tmp_path):
    db, m = small(tmp_path, mirror=False)
    r = database_ranges(db, m)[1]                       # file frames [500, 620)
    assert manifest_range(r, 510, 560) == {"range": [510, 560], "tags": ["run", "turn"]}
    assert manifest_range(r, 500, 620)["range"] == [500, 620]
    for start, stop, words in ((560, 560, "empty"), (560, 510, "empty"), (600, 700, "past the end"),
                               (400, 520, "before the start")):
        with pytest.raises(RangeSelectionError) as e:
            check_selection(r, start, stop)
        msg = str(e.value)
        assert isinstance(e.value, InputError)
        assert "\n" not in msg and msg.startswith(str(TAKE)) and words in msg, msg

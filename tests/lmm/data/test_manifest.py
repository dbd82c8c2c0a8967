"""Manifest validation: every field's accepted range and every list's size limit, checked before any
work, each failure one ManifestError line naming the file and the field (never a file's contents)."""
from __future__ import annotations

import json
from pathlib import Path

import pytest

from lmm import DEFAULT_MANIFEST
from lmm.data import manifest as manifest_module
from lmm.data.manifest import ManifestError, load_manifest
from lmm.errors import InputError

TAKE = DEFAULT_MANIFEST.parent / "lafan1" / "obstacles3_subject4.bvh.gz"


def write(tmp_path: Path, filename: str = "m.json", **fields) -> Path:
    data = {"name": "small", "clips": [{"file": str(TAKE), "ranges": [[100, 400]]}]}
    data.update(fields)
    path = tmp_path / filename
    path.write_text(json.dumps(data))
    return path


def refused(path: Path, field: str, *words: str) -> ManifestError:
    with pytest.raises(ManifestError) as info:
        load_manifest(path)
    e = info.value
    msg = str(e)
    assert isinstance(e, InputError)
    assert "\n" not in msg and path.name in msg and f"field '{field}'" in msg, msg
    for w in words:
        assert w in msg, msg
    return e


@pytest.mark.parametrize("fields, field, words", [
    ({"name": "/../../../../x"}, "name", ["'/'"]),
    ({"name": "sub/dir/name"}, "name", ["'/'"]),
    ({"name": "back\\slash"}, "name", ["'\\'"]),
    ({"name": ".."}, "name", []),
    ({"name": "a" * 300}, "name", ["at most 80 characters"]),
    ({"name": "a\x00b"}, "name", ["NUL"]),
    ({"name": "tab\there"}, "name", ["control"]),
    ({"name": ""}, "name", ["non-empty"]),
    ({"name": 42}, "name", ["string"]),
    ({"description": "x" * 5000}, "description", ["4096"]),
    ({"simulation": {"order": -1}}, "simulation.order", ["from 0 to 7"]),
    ({"simulation": {"order": 8}}, "simulation.order", ["from 0 to 7"]),
    ({"simulation": {"position_window": 603}}, "simulation.position_window", ["from 1 to 601"]),
    ({"simulation": {"direction_window": -1}}, "simulation.direction_window", []),
    ({"simulation": {"ordr": 3}}, "simulation.ordr", ["unknown field"]),
    ({"speed_scale": 1e-9}, "speed_scale", ["from 0.1 to 10"]),
    ({"speed_scale": 11}, "speed_scale", ["from 0.1 to 10"]),
    ({"target_fps": 1e12}, "target_fps", ["from 10 to 240"]),
    ({"target_fps": 1e5}, "target_fps", ["from 10 to 240"]),
    ({"target_fps": 5}, "target_fps", ["from 10 to 240"]),
    ({"unit_scale": 1e9}, "unit_scale", ["from 0.0001 to 100"]),
    ({"contacts": {"median_window": 1000001}}, "contacts.median_window", ["from 1 to 61"]),
    ({"contacts": {"median_window": 4}}, "contacts.median_window", ["odd"]),
    ({"contacts": {"speed_threshold_m_s": 1e9}}, "contacts.speed_threshold_m_s", ["to 10"]),
    ({"contacts": {"window": 5}}, "contacts.window", ["unknown field"]),
    ({"hips_forward_axis": [1e308, 0, 0]}, "hips_forward_axis[0]", ["from -1000 to 1000"]),
    ({"mirror_name_pairs": [["L", "R"]] * 17}, "mirror_name_pairs", ["at most 16"]),
    ({"bones": {f"r{i}": "Hips" for i in range(65)}}, "bones", ["at most 64"]),
    ({"clips": [{"file": str(TAKE), "ranges": [[0, 10**7]]}]}, "clips[0].ranges[0]", ["5000000"]),
    ({"clips": [{"file": str(TAKE), "tags": ["t"] * 33}]}, "clips[0].tags", ["at most 32"]),
    ({"clips": [{"file": str(TAKE), "tags": ["x" * 33]}]}, "clips[0].tags[0]", ["up to 32"]),
    ({"clips": [{"file": "a\x00b.bvh"}]}, "clips[0].file", ["NUL"]),
    ({"clips": [{"file": "x" * 5000}]}, "clips[0].file", ["at most 4096"]),
    ({"clips": [{"file": "d/" * 1000 + "x" * 300}]}, "clips[0].file", ["no such file"]),
    ({"features": "a\x00b.json"}, "features", ["NUL"]),
])
def test_out_of_range_fields_are_refused(tmp_path, fields, field, words):
    refused(write(tmp_path, **fields), field, *words)


@pytest.mark.parametrize("fields", [
    {"target_fps": 10}, {"target_fps": 240}, {"speed_scale": 0.1}, {"speed_scale": 10},
    {"simulation": {"order": 0, "position_window": 1, "direction_window": 601}},
    {"contacts": {"median_window": 61}}, {"contacts": {"median_window": 1}},
    {"name": "LAFAN1 walks (v2) — ü"}, {"name": "x" * 80}, {"unit_scale": 1.0}, {"unit_scale": 0.001},
])
def test_boundaries_are_accepted(tmp_path, fields):
    load_manifest(write(tmp_path, **fields))


def test_too_many_clips_are_refused_before_any_file_is_looked_at(tmp_path, monkeypatch):
    looked = []
    real_is_file = Path.is_file
    monkeypatch.setattr(Path, "is_file", lambda self: looked.append(self) or real_is_file(self))
    path = write(tmp_path, clips=[{"file": str(TAKE)}] * 10_000)
    refused(path, "clips", "at most 256 clips", "10000")
    many_ranges = [{"file": str(TAKE), "ranges": [[0, 10]] * 100}] * 41
    refused(write(tmp_path, clips=many_ranges), "clips", "at most 4096 ranges", "4100")
    assert looked == []


def test_deep_nesting_is_one_line_not_a_recursion_error(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text('{"name": "x", "clips": ' + "[" * 100_000 + "]" * 100_000 + "}")
    refused(deep, "<file>", "nested deeper")
    shallow = tmp_path / "nine.json"  # parses, but deeper than any manifest needs
    shallow.write_text(json.dumps({"name": "x", "description": "", "clips": [[[[[[[[[1]]]]]]]]]}))
    refused(shallow, "<top>", "nested deeper than 8")
    toml = tmp_path / "deep.toml"
    toml.write_text("clips = " + "[" * 5000 + "]" * 5000 + "\n")
    refused(toml, "<file>", "nested deeper")


def test_huge_numbers_and_files(tmp_path, monkeypatch):
    digits = tmp_path / "digits.json"
    digits.write_text('{"name": "x", "target_fps": ' + "9" * 5000 + "}")
    refused(digits, "<file>", "number too long")
    big = write(tmp_path, "big.json", description="x" * 100)
    monkeypatch.setattr(manifest_module, "MAX_MANIFEST_BYTES", 64)
    refused(big, "<file>", "larger than 64 bytes")


def test_feature_schema_file_nested_deep(tmp_path):
    schema = tmp_path / "schema.json"
    schema.write_text("[" * 100_000 + "]" * 100_000)
    with pytest.raises(ManifestError, match=r"schema.json.*nested deeper"):
        load_manifest(write(tmp_path, features="schema.json"))


def test_error_about_a_clip_path_never_echoes_the_file(tmp_path):
    """A manifest naming a system-like text file: the error says which clip, not what the file holds."""
    from lmm.data.build import build

    secret = tmp_path / "passwd"
    secret.write_text("root:x:0:0:secret-line:/root:/bin/bash\n")
    path = write(tmp_path, clips=[{"file": str(secret)}])
    with pytest.raises(InputError) as info:
        build(load_manifest(path))
    assert "secret-line" not in str(info.value) and "passwd" in str(info.value)

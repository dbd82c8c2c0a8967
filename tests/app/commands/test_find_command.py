"""``lmm-studio find``: the table, the JSON and one-line errors naming the file."""
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from app.cli import main
from lmm.data import bvh

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    from lmm import DEFAULT_MANIFEST
    from lmm.data.manifest import load_manifest

    root = tmp_path_factory.mktemp("data")
    clips = load_manifest(DEFAULT_MANIFEST).clips
    (root / "takes" / "sub").mkdir(parents=True)
    bvh.save(root / "takes" / "a.bvh", bvh.load(clips[0].file).slice(0, 400))
    bvh.save(root / "takes" / "sub" / "b.bvh", bvh.load(clips[4].file).slice(100, 500))
    robot = bvh.load(clips[0].file).slice(0, 100)
    robot.names = [n.replace("Hand", "Paw") for n in robot.names]
    (root / "robots").mkdir()
    bvh.save(root / "robots" / "robot.bvh", robot)
    return root


@pytest.fixture(autouse=True)
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("LMM_STUDIO_CACHE", str(tmp_path / "cache"))


def test_find_prints_a_table_and_writes_json_in_the_files_own_frames(folder, tmp_path, capsys):
    out = tmp_path / "res" / "r.json"
    code = main(["find", str(folder / "takes" / "sub" / "b.bvh"), "--frames", "120:170", "--in",
                 str(folder / "takes" / "sub"),
                 "--top", "3", "--json", str(out), "--include-overlap"])
    assert code == 0
    text = capsys.readouterr().out
    assert "rank" in text and "b.bvh" in text
    results = json.loads(out.read_text())["results"]
    assert len(results) == 3 and set(results[0]) == {"file", "start_frame", "end_frame", "distance"}
    assert results[0] == {"file": "b.bvh", "start_frame": 120, "end_frame": 170, "distance": 0.0}
    assert all(0 <= r["start_frame"] < r["end_frame"] <= 400 for r in results)
    assert [r["distance"] for r in results] == sorted(r["distance"] for r in results)


def test_a_query_inside_the_searched_set_returns_no_window_overlapping_it_by_default(folder, tmp_path, capsys):
    out = tmp_path / "r.json"
    assert main(["find", str(folder / "takes" / "sub" / "b.bvh"), "--frames", "120:170", "--in",
                 str(folder / "takes"), "--top", "20", "--json", str(out)]) == 0
    assert "windows overlapping it left out" in capsys.readouterr().out
    results = json.loads(out.read_text())["results"]
    assert len(results) >= 3 and any(r["file"] == "sub/b.bvh" for r in results)
    assert not [r for r in results if r["file"] == "sub/b.bvh" and r["start_frame"] < 170 and r["end_frame"] > 120]


def test_find_in_a_folder_labels_files_relative_to_it(folder, capsys):
    assert main(["find", str(folder / "takes" / "a.bvh"), "--frames", "10:50", "--in", str(folder / "takes"),
                 "--top", "20", "--quiet"]) == 0
    text = capsys.readouterr().out
    assert "sub/b.bvh" in text and " a.bvh " in text and "index" not in text


@pytest.mark.parametrize("args,words", [
    (["robots/robot.bvh", "--frames", "0:50"], ["robot.bvh: cannot match the key joints left_hand, right_hand"]),
    (["a.bvh", "--frames", "50:50"], ["a.bvh: frames 50:50 are an empty range"]),
    (["a.bvh", "--frames", "300:401"], ["a.bvh: frames 300:401 go past the end of the take (400 frames"]),
    (["a.bvh", "--frames", "0:5"], ["a.bvh frames 0:5: the query is 5 frames", "at least 8"]),
    (["a.bvh", "--frames", "0:50", "--in", "{tmp}"], ["the folder holds no .bvh files"]),
    (["a.bvh", "--frames", "0:50", "--in", "{robots}"], ["robot.bvh: cannot match the key joints"]),
    (["missing.bvh", "--frames", "0:50"], ["missing.bvh"]),
])
def test_bad_input_is_one_line_naming_the_file(folder, tmp_path, capsys, args, words):
    empty = tmp_path / "empty"
    empty.mkdir()
    args = [a.replace("{tmp}", str(empty)).replace("{robots}", str(folder / "robots")) for a in args]
    args[0] = str(folder / ("" if args[0].startswith("robots") else "takes") / args[0])
    assert main(["find", *args, "--quiet"]) == 1
    err = capsys.readouterr().err
    assert err.startswith("lmm-studio find: error: ") and err.count("\n") == 1, err
    for w in words:
        assert w in err, (w, err)


def test_bad_frames_argument_is_a_usage_error(folder, capsys):
    with pytest.raises(SystemExit) as e:
        main(["find", str(folder / "takes" / "a.bvh"), "--frames", "10-20"])
    assert e.value.code == 2 and "expected A:B" in capsys.readouterr().err


def test_without_dtaidistance_find_still_answers_and_says_so_in_one_line(folder, tmp_path):
    code = ("import sys\nsys.modules['dtaidistance'] = None\nfrom app.cli import main\n"
            "sys.exit(main(sys.argv[1:]))\n")
    env = dict(os.environ, LMM_STUDIO_CACHE=str(tmp_path / "cache"), PYTHONPATH=str(ROOT))
    r = subprocess.run([sys.executable, "-c", code, "find", str(folder / "takes" / "a.bvh"),
                        "--frames", "10:60", "--in", str(folder / "takes" / "sub"), "--top", "2"], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 0, r.stderr
    notes = [line for line in r.stderr.splitlines() if line.startswith("note:")]
    assert len(notes) == 1 and "dtaidistance" in notes[0] and "pip install" in notes[0]
    assert "b.bvh" in r.stdout

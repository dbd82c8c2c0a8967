"""Warnings when a database cannot serve the tuning or its bone roles look wrong (lmm.data_fit; build-db,
run and the studio's status text)."""
import json
from pathlib import Path

import pytest

from app.cli import main
from lmm import DEFAULT_MANIFEST, data_fit
from lmm.data.build import load_or_build
from lmm.tuning import Tuning

LAFAN1 = Path(DEFAULT_MANIFEST).parent / "lafan1"
#: standing stretches of three shipped takes (the default manifest's 'idle' ranges): root speed p99 0.17 m/s
SLOW = [("multipleActions1_subject2.bvh.gz", [2971, 3042]), ("multipleActions1_subject3.bvh.gz", [2993, 3105]),
        ("multipleActions1_subject4.bvh.gz", [2045, 2227])]


def write_manifest(path: Path, **bones) -> Path:
    m = json.loads(Path(DEFAULT_MANIFEST).read_text())
    m["name"] = path.stem
    m["bones"] = dict(m["bones"], **bones)
    m["clips"] = [{"file": str(LAFAN1 / f), "ranges": [{"range": r, "tags": ["idle"]}]} for f, r in SLOW]
    path.write_text(json.dumps(m))
    return path


@pytest.fixture(scope="module")
def slow_ankles(tmp_path_factory):
    """A database of slow ranges whose manifest names the ankles (LeftFoot, RightFoot) as the toes."""
    return write_manifest(tmp_path_factory.mktemp("fit") / "slow_ankles.json", left_toe="LeftFoot",
                          right_toe="RightFoot")


def test_the_shipped_database_fits_the_default_tuning():
    db, _ = load_or_build()
    assert data_fit.fit_warnings(db, Tuning()) == [] and data_fit.status_text(db, Tuning()) == ""
    assert 3.0 < data_fit.root_speed_percentile(db) < 3.5 * data_fit.SPEED_MARGIN


def test_slow_data_and_ankles_named_as_toes_are_each_one_line(slow_ankles):
    db, _ = load_or_build(slow_ankles)
    assert data_fit.root_speed_percentile(db) < 1.0
    speeds = data_fit.speed_warnings(db, Tuning())
    assert len(speeds) == 1 and "run_forward_speed 3.5" in speeds[0] and "p99" in speeds[0]
    slow_tuning = Tuning()
    for name in data_fit.SPEED_FIELDS:
        setattr(slow_tuning, name, 0.2)
    assert data_fit.speed_warnings(db, slow_tuning) == []
    roles = data_fit.role_warnings(db)
    assert any("left_foot and left_toe are the same bone LeftFoot" in r for r in roles), roles
    assert any("not the lowest joints" in r and "LeftToe" in r for r in roles), roles
    # the status line's short form: the fastest speed asked against the data's p99, the role lines counted
    status = data_fit.status_text(db, Tuning())
    assert status.startswith("data: the tuning asks for up to 3.5 m/s, the database's root speed p99 is 0."), status
    assert len(roles) == 3 and status.endswith("p99 is 0.17 m/s; 3 bone role problems"), status
    assert data_fit.status_text(db, slow_tuning) == "data: 3 bone role problems"
    fit = data_fit.DataFit(db)
    assert fit.warnings(Tuning()) == data_fit.fit_warnings(db, Tuning()) == speeds + roles
    # a knee named as the foot and the ankle as the toe: the toe is not above the foot, but not the lowest
    knees = write_manifest(slow_ankles.with_name("knees.json"), left_foot="LeftLeg", right_foot="RightLeg",
                           left_toe="LeftFoot", right_toe="RightFoot")
    assert ["not the lowest joints" in r for r in data_fit.role_warnings(load_or_build(knees)[0])] == [True]


def test_build_db_and_run_print_the_warnings(slow_ankles, tmp_path, capsys):
    assert main(["build-db", "--manifest", str(slow_ankles), "--out", str(tmp_path / "db.npz"), "--no-checks",
                 "--quiet"]) == 0
    err = capsys.readouterr().err
    assert sum(line.startswith("warning: ") for line in err.splitlines()) == 4, err
    assert main(["run", "--manifest", str(slow_ankles), "--input", "builtin:circle", "--seconds", "0.5"]) == 0
    err = capsys.readouterr().err
    assert "warning: the tuning asks for speeds the database slow_ankles does not cover" in err, err
    assert sum(line.startswith("warning: bone roles") for line in err.splitlines()) == 3, err

"""Hand-made database caches (issue 36): a valid zip with the right key but arrays that disagree or
ranges outside the frames gave exit 70 later in the runtime. Each is now refused when opened and the
database built again, with one note."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from lmm.data import archive
from lmm.data.build import load_or_build
from lmm.data.database import Database, DatabaseError

CORPUS = Path(__file__).resolve().parents[2] / "corpus"
MANIFEST = CORPUS / "good" / "manifest.json"
sys.path.insert(0, str(CORPUS))
from state_cases import DB_CHANGES as CHANGES  # noqa: E402  (the same caches run through run in the corpus)


def _arrays(db):
    return db.to_archive()


@pytest.mark.parametrize("change", list(CHANGES))
def test_an_inconsistent_cache_is_built_again_with_a_note(tmp_path, change, capsys):
    db, info = load_or_build(MANIFEST, cache_dir=tmp_path)
    arrays, meta = db.to_archive()
    arrays = {k: np.array(v) for k, v in arrays.items()}
    CHANGES[change](arrays, meta)
    archive.write(info.path, arrays, meta, sort_keys=False)
    with pytest.raises(DatabaseError, match="inconsistent database"):
        Database.load(info.path)
    capsys.readouterr()
    again, info2 = load_or_build(MANIFEST, cache_dir=tmp_path)
    err = capsys.readouterr().err
    assert not info2.cached and err.count("\n") == 1 and err.startswith("note: ") and "building" in err, err
    assert again.n_frames == db.n_frames and np.array_equal(again.positions, db.positions)
    assert Database.load(info2.path).n_frames == db.n_frames

"""The studio's file dialogs (input log, tuning preset, reference clip) given a FIFO (issue 36): the GUI
froze in open(); what each dialog calls now refuses it at once in one line naming the file."""
from __future__ import annotations

import os
import threading

import pytest

from app.reference_clip import load_reference_clip
from lmm.data.inputs import open_input
from lmm.errors import InputError
from lmm.tuning import Tuning


@pytest.mark.parametrize("read", [open_input, Tuning.read_preset, load_reference_clip],
                         ids=["input dialog", "preset dialog", "reference dialog"])
def test_a_fifo_chosen_in_a_dialog_is_refused_at_once(tmp_path, read):
    fifo = tmp_path / ("take.bvh" if read is load_reference_clip else "fifo.csv")
    os.mkfifo(fifo)
    outcome = {}

    def call():
        try:
            read(str(fifo))
        except InputError as e:
            outcome["error"] = str(e)

    t = threading.Thread(target=call, daemon=True)
    t.start()
    t.join(10)
    if t.is_alive():   # unblock the reader so the test process can end, then fail
        open(fifo, "wb").close()
        pytest.fail("the read blocked on the FIFO")
    assert "FIFO" in outcome.get("error", "") and str(fifo) in outcome["error"], outcome

"""What ``lmm-studio train`` prints: a progress line per stage and a few summary lines naming the files,
never a line per logged iteration unless ``--verbose`` asks; the losses are in the training log."""
from __future__ import annotations

import csv
import io
from functools import partial

import pytest

pytest.importorskip("torch")

SCREEN_LINES = 24


@pytest.fixture
def small_recipe(monkeypatch):
    """The command's recipe with small networks and no projector cell term (whose neighbour table of every
    database frame takes about 45 s on one thread); the schedule still comes from the command line."""
    from lmm.offline import training as T

    monkeypatch.setattr(T, "Recipe", partial(T.Recipe, hidden=32, projector_neighbours=0))


def train(tmp_path, capsys, *extra) -> tuple[str, str]:
    from app.cli import main

    rc = main(["train", "all", "--iterations", "30", "--batch", "16", "--log-every", "1", "--frames", "2000",
               "--threads", "1", "--out", str(tmp_path), *extra])
    out = capsys.readouterr()
    assert rc == 0, out.err
    return out.out, out.err


def test_train_all_prints_a_screenful_naming_the_weights_and_logs_every_row(tmp_path, capsys, small_recipe):
    out, err = train(tmp_path, capsys)
    lines = (out + err).splitlines()
    assert len(lines) <= SCREEN_LINES, "\n".join(lines)
    assert str(tmp_path / "default.npz") in out and str(tmp_path / "training_log.csv") in out
    assert not [line for line in lines if line.startswith("[")], "loss lines without --verbose"
    for stage in ("decompressor", "stepper", "projector"):   # a progress line and a summary line each
        assert [line for line in err.splitlines() if line.startswith(f"{stage} [")], err
        assert [line for line in out.splitlines() if line.startswith(stage) and "loss" in line], out
    with open(tmp_path / "training_log.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == 3 * 30   # --log-every 1: every iteration's losses are in the file


def test_verbose_prints_every_logged_row(tmp_path, capsys, small_recipe):
    _, err = train(tmp_path, capsys, "--verbose")
    loss_lines = [line for line in err.splitlines() if line.startswith("[")]
    assert len(loss_lines) == 3 * 30 and loss_lines[0].startswith("[decompressor] it 1 loss ")


def test_quiet_and_verbose_together_are_refused(tmp_path, capsys):
    from app.cli import main

    with pytest.raises(SystemExit) as e:
        main(["train", "--quiet", "--verbose", "--out", str(tmp_path)])
    assert e.value.code == 2 and "not allowed with" in capsys.readouterr().err


class Terminal(io.StringIO):
    def isatty(self) -> bool:
        return True


def test_on_a_terminal_a_stage_is_one_line_redrawn_in_place():
    from lmm.offline.training_loop import LossLog

    term = Terminal()
    log = LossLog("stepper", 50, 5, stream=term)
    log.progress.min_interval_s = 0.0   # draw at every iteration: the most a fast machine could
    for it in range(50):
        log.add(it, 1e-3, {"loss": 1.0 / (it + 1)})
    log.close()
    text = term.getvalue()
    assert text.count("\n") == 1 and text.endswith("\n") and text.count("\r") == 50
    assert "50/50" in text.splitlines()[-1].split("\r")[-1] and "loss 0.0200" in text
    assert len(log.rows) == 10

"""The one error place of ``lmm-studio`` (app/cli.py): expected errors are one line and exit 1, bugs one
line plus a trace file and exit 70, bad arguments one line and exit 2; never a raw traceback."""
import errno
import subprocess
import sys
import types
from pathlib import Path

import pytest

from app import cli
from lmm.errors import InputError

ROOT = Path(__file__).resolve().parents[3]


@pytest.fixture
def fake_command(monkeypatch, tmp_path):
    """Install ``lmm-studio fake`` whose main raises what the test puts in ``box['raise']``."""
    box = {}
    module = types.ModuleType("app.commands.fake")

    def add_arguments(p):
        p.add_argument("--count", type=int, default=1)

    def main(args):
        if "raise" in box:
            raise box["raise"]
        return 0

    module.add_arguments, module.main = add_arguments, main
    monkeypatch.setitem(sys.modules, "app.commands.fake", module)
    monkeypatch.setitem(cli.COMMANDS, "fake", ("fake", "a test command"))
    monkeypatch.setenv("LMM_STUDIO_CACHE", str(tmp_path / "cache"))
    return box


def _lines(text):
    return [ln for ln in text.splitlines() if ln.strip()]


def test_input_error_is_one_line_exit_1(fake_command, capsys):
    class PresetError(InputError):
        pass

    fake_command["raise"] = PresetError("presets/bad.json: field 'top_k': expected a number,\ngot 'x'")
    assert cli.main(["fake"]) == cli.EXIT_INPUT_ERROR == 1
    err = capsys.readouterr().err
    assert _lines(err) == ["lmm-studio fake: error: presets/bad.json: field 'top_k': expected a number, got 'x'"]


@pytest.mark.parametrize("exc, words", [
    (PermissionError(errno.EACCES, "Permission denied", "/ro/metrics.json"), "/ro/metrics.json: Permission denied"),
    (OSError(errno.ENOSPC, "No space left on device", "/full/out.npz"), "/full/out.npz: No space left on device"),
    (FileNotFoundError(errno.ENOENT, "No such file or directory", "x.bvh"), "x.bvh: No such file or directory"),
    (OSError(errno.ENOSPC, "No space left on device"), "No space left on device"),
])
def test_os_errors_name_the_path_exit_1(fake_command, capsys, exc, words):
    fake_command["raise"] = exc
    assert cli.main(["fake"]) == 1
    lines = _lines(capsys.readouterr().err)
    assert lines == [f"lmm-studio fake: error: {words}"]


def test_unexpected_error_is_one_line_with_a_trace_file_exit_70(fake_command, capsys, tmp_path):
    fake_command["raise"] = KeyError("n_bones")
    assert cli.main(["fake"]) == cli.EXIT_INTERNAL_ERROR == 70
    lines = _lines(capsys.readouterr().err)
    assert len(lines) == 1 and "Traceback" not in lines[0]
    assert lines[0].startswith("lmm-studio fake: internal error: KeyError: 'n_bones' (full trace: ")
    trace = Path(lines[0].split("(full trace: ", 1)[1].rstrip(")"))
    assert trace.parent == tmp_path / "cache" / "logs" and trace.is_file()
    text = trace.read_text()
    assert "Traceback" in text and "KeyError: 'n_bones'" in text and "def main" not in text


def test_unexpected_error_when_the_trace_cannot_be_written(fake_command, capsys, tmp_path, monkeypatch):
    blocker = tmp_path / "cache"
    blocker.write_text("a file where the cache folder should be")
    fake_command["raise"] = RecursionError("maximum recursion depth exceeded")
    assert cli.main(["fake"]) == 70
    lines = _lines(capsys.readouterr().err)
    assert lines == ["lmm-studio fake: internal error: RecursionError: maximum recursion depth exceeded "
                     "(the full trace could not be written)"]


def test_long_messages_are_cut(fake_command, capsys):
    fake_command["raise"] = InputError("x" * 5000)
    assert cli.main(["fake"]) == 1
    (line,) = _lines(capsys.readouterr().err)
    assert len(line) <= len("lmm-studio fake: error: ") + cli.MAX_MESSAGE_CHARS and line.endswith("...")


def test_bad_argument_is_one_line_exit_2(fake_command, capsys):
    with pytest.raises(SystemExit) as e:
        cli.main(["fake", "--count", "many"])
    assert e.value.code == 2
    (line,) = _lines(capsys.readouterr().err)
    assert line.startswith("lmm-studio fake: error: argument --count: invalid int value: 'many'")


def test_success_and_interrupt(fake_command, capsys):
    assert cli.main(["fake"]) == 0
    fake_command["raise"] = KeyboardInterrupt()
    assert cli.main(["fake"]) == 130
    assert capsys.readouterr().err == ""


def test_subprocess_never_prints_a_traceback(tmp_path):
    """End to end: a real command with a missing file, as a user runs it."""
    r = subprocess.run([sys.executable, "-m", "app.cli", "run", "--input", str(tmp_path / "nope.csv")],
                       cwd=ROOT, capture_output=True, text=True, timeout=120,
                       env={**__import__("os").environ, "LMM_STUDIO_CACHE": str(tmp_path / "cache")})
    assert r.returncode == 1 and "Traceback" not in r.stderr
    assert _lines(r.stderr) == [f"lmm-studio run: error: {tmp_path / 'nope.csv'}: no such input file"]


@pytest.mark.parametrize("args, words", [
    (["--seconds", "inf"], "argument --seconds: inf is outside [0, 86400] s"),
    (["--seconds", "1e308"], "argument --seconds: 1e308 is outside"),
    (["--seconds", "nan"], "argument --seconds: nan is outside"),
    (["--seconds", "-1"], "argument --seconds: -1 is outside"),
    (["--fps", "inf"], "argument --fps: inf is outside [1, 1000] Hz"),
    (["--fps", "0"], "argument --fps: 0 is outside [1, 1000] Hz"),
    (["--fps", "sixty"], "argument --fps: expected a number, got 'sixty'"),
])
def test_run_numbers_out_of_range_are_refused_by_argparse(capsys, args, words):
    with pytest.raises(SystemExit) as e:
        cli.main(["run", "--input", "builtin:circle", *args])
    assert e.value.code == 2
    (line,) = _lines(capsys.readouterr().err)
    assert line.startswith(f"lmm-studio run: error: {words}"), line


def test_number_in_accepts_the_range_ends():
    parse = cli.number_in(1, 10, integer=True)
    assert parse("1") == 1 and parse("10") == 10 and isinstance(parse("5"), int)
    with pytest.raises(Exception, match="expected an integer"):
        parse("2.5")


def test_unknown_command_is_one_line(capsys):
    assert cli.main(["no-such-command"]) == 2
    assert _lines(capsys.readouterr().err) == [
        f"lmm-studio: error: unknown command 'no-such-command' (commands: {', '.join(cli.COMMANDS)})"]

"""The ``lmm-studio`` command.

``lmm-studio`` with no subcommand opens the studio; subcommands live one per module in
``app/commands`` and are imported only when used, so ``lmm-studio run`` never pays for
dearpygui and ``lmm-studio build-db`` never pays for torch.

Errors have one place, :func:`main`: an expected error (:class:`lmm.errors.InputError`, a bad file, field
or argument; or ``OSError``, a missing file or a read-only or full target) prints
``lmm-studio COMMAND: error: <one line>`` on stderr and exits with 1. Anything else is a bug: one line
``lmm-studio COMMAND: internal error: <Type>: <message> (full trace: <file>)``, the trace written under
the cache folder's ``logs/``, exit code 70. Never a raw traceback.
"""
from __future__ import annotations

import argparse
import importlib
import os
import sys
import time
import traceback

EXIT_INPUT_ERROR = 1    # a bad file, field or argument, or a target that cannot be written
EXIT_INTERNAL_ERROR = 70  # EX_SOFTWARE (sysexits.h): a bug, the trace is in a log file
MAX_MESSAGE_CHARS = 1000  # one terminal-readable line; a longer message is cut with "..."

# name -> (module under app.commands, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "studio": ("studio", "open the studio (default when no command is given)"),
    "build-db": ("build_db", "build (or load from cache) the motion database and print its size"),
    "check-data": ("check_data", "check a manifest's takes (T-pose, climbing, sliding, outliers) and its coverage"),
    "coverage": ("coverage", "map the database's feature space, speed x turn rate and histograms (PNG, JSON)"),
    "view": ("view", "play a BVH, glTF or FBX file or a session in a 3D window, or render it headless (PNG, mp4)"),
    "train": ("train", "train the learned motion matching networks (needs torch)"),
    "eval": ("eval", "quality metrics of the learned motion matching networks"),
    "export-onnx": ("export_onnx", "export the decompressor, stepper and projector as ONNX"),
    "export-gltf": ("export_gltf", "a recording, take or session as glTF 2.0 (.glb): skeleton, animation, capsule body"),
    "run": ("run", "drive a controller headless from an input log or built-in scenario (record, metrics)"),
    "bench": ("bench", "runtime benchmarks (search, frame) as a table and nested JSON"),
    "find": ("find", "motion search by example: the windows of a manifest or folder most like a BVH frame range"),
    "compare": ("compare", "DTW-aligned rotation and position error between two motions of one skeleton"),
    "input-from": ("input_from", "derive the controller input that follows a take's root path (an input log)"),
    "physics": ("physics", "is this motion physically possible: root residual force, penetration, sliding (needs mujoco)"),
    "eval-search": ("eval_search", "motion search by example: learned encoder vs classifier vs features on a folder"),
    "replay": ("replay", "re-simulate a session file headless, check its pose fingerprints, or branch it (--tuning)"),
    "trace": ("trace", "one row per tick and controller of a session (matched frame, costs, root, contacts): CSV or parquet"),
    "ab": ("ab", "compare a session's recorded arm A with arm B under another tuning: metrics JSON and PNG plots"),
}


def number_in(lo: float, hi: float, integer: bool = False, unit: str = ""):
    """An argparse ``type`` accepting a finite number in ``[lo, hi]`` (an integer if ``integer``); the
    error names the range, e.g. ``argument --fps: 0 is outside [1, 1000] Hz``. NaN and inf never pass."""
    import math

    def parse(text: str):
        try:
            value = int(text) if integer else float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected {'an integer' if integer else 'a number'}, "
                                             f"got {text[:40]!r}") from None
        if not (math.isfinite(value) and lo <= value <= hi):
            shown = f"[{lo}, {hi}]" if integer else f"[{lo:g}, {hi:g}]"
            raise argparse.ArgumentTypeError(f"{text[:40]} is outside {shown}{' ' + unit if unit else ''}")
        return value

    parse.__name__ = "integer" if integer else "number"
    return parse


class CommandParser(argparse.ArgumentParser):
    """argparse with a one-line error (argparse prints the usage block too): ``PROG: error: MSG``, exit 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {one_line(message)} (see '{self.prog} --help')\n")


def _top_parser() -> argparse.ArgumentParser:
    lines = "\n".join(f"  {name:<12} {help_text}" for name, (_, help_text) in COMMANDS.items())
    return argparse.ArgumentParser(
        prog="lmm-studio",
        description="Visual debugger and tuning studio for Motion Matching and Learned Motion Matching.",
        epilog=f"commands:\n{lines}\n\nRun 'lmm-studio COMMAND --help' for a command's options.",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def main(argv: list[str] | None = None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    # no subcommand (or only studio options): open the studio
    if (not argv or (argv[0].startswith("-") and argv[0] not in ("-h", "--help"))) and "studio" in COMMANDS:
        argv = ["studio", *argv]
    if not argv or argv[0] in ("-h", "--help"):
        _top_parser().print_help()
        return 0
    name = argv[0]
    if name not in COMMANDS:
        print(f"lmm-studio: error: unknown command {name[:40]!r} (commands: {', '.join(COMMANDS)})", file=sys.stderr)
        return 2
    module_name, help_text = COMMANDS[name]
    try:
        # import only the chosen command: `run` never pays for dearpygui, `build-db` never for torch
        module = importlib.import_module(f"app.commands.{module_name}")
        parser = CommandParser(prog=f"lmm-studio {name}", description=help_text)
        module.add_arguments(parser)
    except Exception as e:  # noqa: BLE001 - a broken install is still reported in one line
        return report_error(name, e)
    args = parser.parse_args(argv[1:])  # a bad argument: one line, exit 2
    args.command = name
    # the studio has its own shutdown; every other command ends on SIGTERM as on Ctrl-C
    previous_sigterm = _terminate_like_interrupt() if name != "studio" else None
    try:
        return int(module.main(args) or 0)
    except Terminated:
        return 128 + 15
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `lmm-studio ... | head`: the reader left, which is not an error
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0
    except Exception as e:  # noqa: BLE001 - the one place that turns every error into one line
        return report_error(name, e)
    finally:
        _release_output_locks()
        if previous_sigterm is not None:
            import signal

            signal.signal(signal.SIGTERM, previous_sigterm)


class Terminated(KeyboardInterrupt):
    """SIGTERM, raised where the command is so its ``finally`` blocks and context managers run (temporary
    files and folders removed, worker pools stopped) exactly as on Ctrl-C; exit status 143."""


def _terminate_like_interrupt():
    """SIGTERM (``timeout``, ``kill``) unwinds the command like SIGINT. A process forked by the command
    (a worker, a helper process) that inherits the handler just ends, silently, as SIGTERM would end it."""
    import signal

    owner = os.getpid()

    def handler(signum, frame):
        if os.getpid() != owner:
            os._exit(128 + 15)
        raise Terminated()

    try:
        return signal.signal(signal.SIGTERM, handler)   # the handler before, put back when the command ends
    except ValueError:   # not the main thread (a test calling main from a thread): leave it
        return None


def _release_output_locks() -> None:
    """The command's output locks (:mod:`lmm.data.outputs`), released once it returns."""
    outputs = sys.modules.get("lmm.data.outputs")
    if outputs is not None:
        outputs.release_locks()


def one_line(text: str) -> str:
    """``text`` as a single line (newlines and tabs become spaces), cut to ``MAX_MESSAGE_CHARS``."""
    line = " ".join(str(text).split())
    return line if len(line) <= MAX_MESSAGE_CHARS else line[:MAX_MESSAGE_CHARS - 3] + "..."


def describe_os_error(e: OSError) -> str:
    """``'PATH: reason'`` for an ``OSError`` (``'[Errno 13] Permission denied: ...'`` reads worse)."""
    if e.strerror and e.filename is not None:
        where = os.fsdecode(e.filename) if isinstance(e.filename, bytes) else str(e.filename)
        if e.filename2 is not None:
            where += f" -> {e.filename2}"
        return f"{where}: {e.strerror}"
    return e.strerror or str(e) or type(e).__name__


def is_expected(e: BaseException) -> bool:
    """True for errors a user causes (bad input, unwritable target); False for bugs."""
    from lmm.errors import InputError

    return isinstance(e, (InputError, OSError))


def report_error(command: str, e: BaseException, stderr=None) -> int:
    """Print ``e`` as one line on ``stderr`` and return the exit code (see the module docstring)."""
    stderr = stderr or sys.stderr
    prog = f"lmm-studio {command}"
    try:
        expected = is_expected(e)
    except Exception:  # noqa: BLE001 - lmm itself cannot be imported: certainly not expected
        expected = False
    if expected:
        text = describe_os_error(e) if isinstance(e, OSError) else str(e)
        print(f"{prog}: error: {one_line(text or type(e).__name__)}", file=stderr)
        return EXIT_INPUT_ERROR
    trace = write_trace(command, e)
    where = f"full trace: {trace}" if trace else "the full trace could not be written"
    print(f"{prog}: internal error: {one_line(f'{type(e).__name__}: {e}')} ({where})", file=stderr)
    return EXIT_INTERNAL_ERROR


def logs_dir():
    """``logs/`` in the cache folder (``LMM_STUDIO_CACHE``, else the user cache), where traces go."""
    from pathlib import Path

    try:
        from lmm.data.cache import default_cache_dir

        return Path(default_cache_dir()) / "logs"
    except Exception:  # noqa: BLE001 - the database module itself may be what is broken
        import tempfile

        return Path(tempfile.gettempdir()) / "lmm-studio-logs"


def write_trace(command: str, e: BaseException):
    """Write ``e``'s traceback to a new file under :func:`logs_dir`; its path, or None if impossible."""
    try:
        folder = logs_dir()
        folder.mkdir(parents=True, exist_ok=True)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        path = folder / f"{command}-{stamp}-{os.getpid()}.txt"
        text = "".join(traceback.format_exception(type(e), e, e.__traceback__))
        with open(path, "w", encoding="utf-8") as f:
            f.write(f"lmm-studio {command} (python {sys.version.split()[0]}, argv {sys.argv!r})\n{text}")
        return path
    except Exception:  # noqa: BLE001 - a full disk must not turn the report into a traceback
        return None


if __name__ == "__main__":
    sys.exit(main())

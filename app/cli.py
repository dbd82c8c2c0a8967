"""The ``lmm-studio`` command.

``lmm-studio`` with no subcommand opens the studio; subcommands live one per module in
``app/commands`` and are imported only when used, so ``lmm-studio run`` never pays for
dearpygui and ``lmm-studio build-db`` never pays for torch.
"""
from __future__ import annotations

import argparse
import importlib
import sys

# name -> (module under app.commands, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "studio": ("studio", "open the studio (default when no command is given)"),
    "build-db": ("build_db", "build (or load from cache) the motion database and print its size"),
    "check-data": ("check_data", "check a manifest's takes (T-pose, climbing, sliding, outliers) and its coverage"),
    "view": ("view", "play a BVH file in a 3D window"),
    "train": ("train", "train the learned motion matching networks (needs torch)"),
    "eval": ("eval", "quality metrics of the learned motion matching networks"),
    "export-onnx": ("export_onnx", "export the decompressor, stepper and projector as ONNX"),
    "run": ("run", "drive a controller headless from an input log or built-in scenario (record, metrics)"),
    "bench": ("bench", "runtime benchmarks (search, frame) as a table and nested JSON"),
}


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
        _top_parser().print_usage(sys.stderr)
        print(f"lmm-studio: error: unknown command {name!r} (commands: {', '.join(COMMANDS)})", file=sys.stderr)
        return 2
    module_name, help_text = COMMANDS[name]
    # import only the chosen command: `run` never pays for dearpygui, `build-db` never for torch
    module = importlib.import_module(f"app.commands.{module_name}")
    parser = argparse.ArgumentParser(prog=f"lmm-studio {name}", description=help_text)
    module.add_arguments(parser)
    args = parser.parse_args(argv[1:])
    args.command = name
    try:
        return int(module.main(args) or 0)
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:  # `lmm-studio ... | head`: the reader left, which is not an error
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0


if __name__ == "__main__":
    sys.exit(main())

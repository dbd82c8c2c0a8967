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
    "build-db": ("build_db", "build (or load from cache) the motion database and print its size"),
    "view": ("view", "play a BVH file in a 3D window"),
}


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="lmm-studio",
        description="Visual debugger and tuning studio for Motion Matching and Learned Motion Matching.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module)
        importlib.import_module(f"app.commands.{module}").add_arguments(p)
    return parser


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    # no subcommand (or only studio options): open the studio
    if not argv or argv[0].startswith("-") and argv[0] not in ("-h", "--help"):
        if "studio" in COMMANDS:
            argv = ["studio", *argv]
    parser = _parser()
    args = parser.parse_args(argv)
    if args.command is None:
        parser.print_help()
        return 0
    module = importlib.import_module(f"app.commands.{args._module}")
    try:
        return int(module.main(args) or 0)
    except KeyboardInterrupt:
        return 130


if __name__ == "__main__":
    sys.exit(main())

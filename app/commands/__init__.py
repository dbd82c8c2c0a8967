"""One module per ``lmm-studio`` subcommand; each defines ``add_arguments(parser)`` and ``main(args) -> int``."""

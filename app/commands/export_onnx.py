"""``lmm-studio export-onnx --out DIR``: the decompressor, stepper and projector as ONNX files."""
from __future__ import annotations

import sys
from pathlib import Path


def add_arguments(p) -> None:
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--weights", help="runtime weights (default: the shipped lmm/data/weights/default.npz)")


def main(args) -> int:
    from app.commands.extras import require
    if not require("export-onnx", "onnx"):
        return 2
    from lmm.learned import DEFAULT_WEIGHTS, LMMNetworks
    from lmm.data.weights import WeightsError

    from lmm.offline.onnx_export import export_networks

    try:
        nets = LMMNetworks.load(Path(args.weights) if args.weights else DEFAULT_WEIGHTS)
    except WeightsError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    for path in export_networks(nets, args.out):
        print(path)
    return 0

"""``lmm-studio export-onnx --out DIR``: the decompressor, stepper and projector as ONNX files."""
from __future__ import annotations

from pathlib import Path


def add_arguments(p) -> None:
    p.add_argument("--out", required=True, help="output folder")
    p.add_argument("--weights", help="runtime weights (default: the shipped lmm/data/weights/default.npz)")


def main(args) -> int:
    from app.commands.extras import require
    if not require("export-onnx", "onnx"):
        return 2
    from lmm.data.atomic import check_writable
    from lmm.learned import DEFAULT_WEIGHTS, LMMNetworks
    from lmm.offline.onnx_export import export_networks

    check_writable(Path(args.out) / "decompressor.onnx")  # a read-only or file --out: one line, exit 1
    nets = LMMNetworks.load(Path(args.weights) if args.weights else DEFAULT_WEIGHTS)  # WeightsError: file + field
    for path in export_networks(nets, args.out):
        print(path)
    return 0

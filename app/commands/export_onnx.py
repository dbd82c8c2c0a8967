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
    from lmm.data.outputs import check_outputs
    from lmm.learned import DEFAULT_WEIGHTS, RUNTIME_NETWORKS, LMMNetworks
    from lmm.offline.onnx_export import export_networks

    weights = Path(args.weights) if args.weights else DEFAULT_WEIGHTS
    # a read-only or file --out, or one whose files include the weights: one line, exit 1
    check_outputs([("--out", Path(args.out) / f"{name}.onnx") for name in RUNTIME_NETWORKS], [("--weights", weights)])
    from lmm.data.leftovers import remove_stale
    remove_stale(args.out)   # what a killed export left half-written there
    nets = LMMNetworks.load(weights)  # WeightsError: file + field
    for path in export_networks(nets, args.out):
        print(path)
    return 0

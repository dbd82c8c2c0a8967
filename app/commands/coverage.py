"""``lmm-studio coverage``: where in feature space a manifest's database holds motion.

    lmm-studio coverage [--manifest M] --png OUT [--json OUT]

Builds (or loads from the cache) the manifest's database and its matching features, then draws a 2D
map of the normalised, weighted feature vectors (PCA) coloured by tag, a root speed x turning-rate heat
map and per-channel histograms (``--png``), and writes the PCA axes and explained variance, the heat
map's bins and the histograms as JSON (``--json``). See :mod:`lmm.coverage`.
"""
from __future__ import annotations

import sys


def add_arguments(p) -> None:
    p.add_argument("--manifest", help="dataset manifest (JSON or TOML); default: the shipped LAFAN1 locomotion set")
    p.add_argument("--png", metavar="OUT", help="draw the map, heat map and histograms as a PNG here")
    p.add_argument("--json", metavar="OUT", help="write the PCA axes, heat map bins and histograms here as JSON")


def main(args) -> int:
    from lmm import DEFAULT_MANIFEST
    from lmm.coverage import build_coverage
    from lmm.data.build import load_or_build
    from lmm.features import build_features

    if not args.png and not args.json:
        print("lmm-studio coverage: error: nothing to write: give --png OUT and/or --json OUT", file=sys.stderr)
        return 2
    from lmm.data.build import manifest_inputs
    from lmm.data.outputs import check_outputs

    manifest = args.manifest or DEFAULT_MANIFEST
    check_outputs([("--png", args.png), ("--json", args.json)], manifest_inputs(manifest))
    db, _ = load_or_build(manifest)
    features = build_features(db)
    cov = build_coverage(db, features)
    ratio = cov.pca.variance_ratio
    filled = cov.heatmap.seconds > 0
    print(f"database  {db.name}: {cov.n_frames} frames ({cov.n_frames / cov.fps:.0f} s), {features.n_dims}-D features")
    print(f"map       PC1 {100 * ratio[0]:.1f}% + PC2 {100 * ratio[1]:.1f}% of the variance")
    print(f"speed x turn  {int(filled.sum())} of {filled.size} cells hold motion "
          f"(speed 0-{cov.heatmap.speed_edges_m_s[-1]:g} m/s, turn rate +-{cov.heatmap.turn_edges_deg_s[-1]:g} deg/s)")
    if args.json:
        from lmm.data.jsonio import write_json

        write_json(args.json, {"manifest": str(manifest), "database": db.name, **cov.to_dict()})
        print(f"wrote     {args.json}")
    if args.png:
        from lmm.reporting import draw_coverage_png

        draw_coverage_png(cov, args.png, title=db.name)
        print(f"wrote     {args.png}")
    return 0

"""``lmm-studio find``: motion search by example over a manifest's takes or a folder of BVH files.

    lmm-studio find QUERY.bvh --frames A:B [--in MANIFEST|DIR] [--top K] [--json OUT]

The query is file frames ``[A, B)`` of any BVH file whose key joints (hips, head, hands, feet) can be
matched by name. Every window of every take in ``--in`` (default: the shipped manifest) is searched (the
index is cached, see :mod:`lmm.motion_search.index`); the best matches are re-ranked by DTW and printed
as a table (file as given in the manifest or relative to DIR, start and end in that file's own frames,
distance); ``--json`` writes ``{"results": [{"file", "start_frame", "end_frame", "distance"}]}``. When QUERY
is one of the searched files, windows overlapping its frames are left out (``--include-overlap`` keeps them).
"""
from __future__ import annotations

import argparse
import os
import re
import time


def frame_range(text: str) -> tuple[int, int]:
    """``A:B`` -> ``(A, B)``, non-negative integers (an empty range is refused later, naming the file)."""
    m = re.fullmatch(r"\s*(\d{1,9})\s*:\s*(\d{1,9})\s*", text)
    if not m:
        raise argparse.ArgumentTypeError(f"expected A:B (file frames, B excluded), got {text[:40]!r}")
    return int(m.group(1)), int(m.group(2))


def add_arguments(p) -> None:
    from app.cli import number_in

    p.add_argument("query", metavar="QUERY.bvh", help="the BVH file holding the example motion")
    p.add_argument("--frames", required=True, type=frame_range, metavar="A:B",
                   help="the example: file frames A (included) to B (excluded), in QUERY's own numbering")
    p.add_argument("--in", dest="where", metavar="MANIFEST|DIR",
                   help="search the takes of this manifest or every .bvh under this folder "
                        "(default: the shipped LAFAN1 manifest)")
    p.add_argument("--top", type=number_in(1, 1000, integer=True), default=10, metavar="K",
                   help="how many results (default 10)")
    p.add_argument("--json", metavar="OUT", help="write the results here as JSON")
    p.add_argument("--no-rerank", action="store_true", help="keep the embedding order (no DTW re-ranking)")
    overlap = p.add_mutually_exclusive_group()
    overlap.add_argument("--exclude-overlap", dest="exclude_overlap", action="store_true",
                         help="leave out windows overlapping the query's frames (the default when QUERY is one "
                              "of the searched files: else the query itself ranks first)")
    overlap.add_argument("--include-overlap", dest="exclude_overlap", action="store_false",
                         help="keep windows overlapping the query's frames")
    p.set_defaults(exclude_overlap=None)
    p.add_argument("--rebuild", action="store_true", help="ignore the cached index and build it again")
    p.add_argument("--quiet", action="store_true", help="no progress bar and no summary, only the table")


def main(args) -> int:
    from lmm import DEFAULT_MANIFEST
    from lmm.motion_search.index import RERANK_TOP, MotionIndex, SearchError, query_from_bvh, sources_from
    from lmm.progress import ProgressCallback

    if not args.quiet:
        from app.commands.extras import suggest
        from lmm.motion_search.dtw import have_dtaidistance

        suggest("find", "dtaidistance", "re-ranks by DTW in numpy (about 7x slower)", have_dtaidistance())
    from lmm.data.outputs import check_outputs

    # before the work, not after it; never over the query or the manifest
    check_outputs([("--json", args.json)], [("QUERY", args.query), ("--in", args.where)])
    a, b = args.frames
    if a >= b:
        raise SearchError(f"{args.query}: frames {a}:{b} are an empty range")
    sources = sources_from(args.where or DEFAULT_MANIFEST)
    # a query from a file the index holds is cut from the index (no second read of the file)
    indexed = {os.path.realpath(s.path) for s in sources}
    query = None if os.path.realpath(args.query) in indexed else query_from_bvh(args.query, args.frames)
    with ProgressCallback("find: indexing", quiet=args.quiet, skip_start=True) as progress:
        index = MotionIndex.build(sources, rebuild=args.rebuild, progress=progress)
    source = index.source_of(args.query)
    if query is None:
        query = index.query_range(source, args.frames, args.query)
    # the query's own frames (and windows overlapping them) are left out unless asked for
    exclude = None
    if source is not None and args.exclude_overlap is not False:
        exclude = (source, *index.resampled_range(source, args.frames))
    t0 = time.perf_counter()
    matches = index.search(query, top=args.top, rerank=0 if args.no_rerank else RERANK_TOP, exclude=exclude)
    search_ms = (time.perf_counter() - t0) * 1000.0
    if not args.quiet:
        how = "cached" if index.from_cache else "built"
        print(f"index   {len(sources)} files, {index.n_windows} windows, embedder {index.embedder.name} "
              f"({how} in {index.build_seconds:.2f} s)")
        print(f"query   {args.query} frames {args.frames[0]}:{args.frames[1]} "
              f"({len(query)} frames at 30 fps); search {search_ms:.0f} ms"
              + ("; windows overlapping it left out (--include-overlap keeps them)" if exclude else ""))
    print(format_table(matches))
    if args.json:
        from lmm.data.jsonio import write_json

        write_json(args.json, {"query": {"file": args.query, "start_frame": args.frames[0],
                                         "end_frame": args.frames[1]},
                               "results": [m.to_dict() for m in matches]})
    return 0


def format_table(matches) -> str:
    if not matches:
        return "no results"
    width = max(4, *(len(m.file) for m in matches))
    lines = [f"{'rank':>4}  {'file':<{width}}  {'start':>7}  {'end':>7}  {'distance':>9}"]
    for i, m in enumerate(matches, 1):
        lines.append(f"{i:>4}  {m.file:<{width}}  {m.start_frame:>7}  {m.end_frame:>7}  {m.distance:>9.4f}")
    return "\n".join(lines)

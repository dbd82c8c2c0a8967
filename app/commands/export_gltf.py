"""``lmm-studio export-gltf``: a recording or take as a glTF 2.0 binary that any glTF viewer, engine or Blender opens.

    lmm-studio export-gltf REC.bvh --out REC.glb                 # skeleton, animation and a capsule body
    lmm-studio export-gltf run.lmmsession --out run.glb --mesh none
    lmm-studio export-gltf take.fbx --out take.glb               # any file `view` reads

The skeleton is a node hierarchy with the file's joint names and a skin; the animation has a rotation channel
per joint and a translation channel per joint the file moves, one keyframe per frame at the file's rate; metres
(the file's unit is guessed from its skeleton's size unless ``--unit-scale`` says it). A session is replayed
headless first (as ``replay --record`` does) and its first (or ``--controller``) character exported. Needs the
``formats`` extra (pygltflib). See :mod:`lmm.data.gltf_write`.
"""
from __future__ import annotations

import os
import tempfile

from app.cli import number_in


def add_arguments(p) -> None:
    p.add_argument("file", metavar="REC.bvh|SESSION", help="a BVH (a recording or a take), glTF or FBX file, "
                   "or a session file (replayed to get its animation)")
    p.add_argument("--out", required=True, metavar="F.glb", help="the .glb file to write")
    p.add_argument("--mesh", choices=("capsules", "none"), default="capsules",
                   help="capsules: a skinned capsule body so the motion plays in any viewer (default); "
                        "none: the skeleton alone")
    p.add_argument("--unit-scale", type=number_in(1e-4, 100.0, unit="m"), default=None, metavar="M",
                   help="metres per file unit (default: guessed from the skeleton's size; 0.01 for glTF/FBX)")
    p.add_argument("--controller", metavar="NAME", help="a session's character to export (default: the first)")


def is_session(path) -> bool:
    """A session is SQLite: its file starts with the SQLite header."""
    from lmm.data.reading import open_regular
    from lmm.errors import InputError

    try:
        with open_regular(path) as f:   # a FIFO is no session (and must not block here): its reader says so
            return f.read(16) == b"SQLite format 3\x00"
    except (OSError, InputError):
        return False


def replay_to_bvh(session, folder: str, controller: str | None = None) -> str:
    """The session replayed headless into a BVH in ``folder`` (the ``replay`` command does the work, and says
    in one line why when it cannot)."""
    from app.cli import main as cli_main
    from lmm.errors import InputError

    out = os.path.join(folder, "replayed.bvh")
    argv = ["replay", os.fspath(session), "--record", out] + (["--controller", controller] if controller else [])
    if cli_main(argv) != 0 or not os.path.exists(out):
        raise InputError(f"{session}: the session could not be replayed (see the line above)")
    return out


def main(args) -> int:
    from lmm.data.gltf_write import require_pygltflib, save_glb
    from lmm.data.motion_files import MOTION_UNIT_M, load_motion
    from lmm.data.outputs import check_outputs
    from lmm.skeleton import guess_unit_scale

    require_pygltflib()                       # before any work: one line when the extra is missing
    check_outputs([("--out", args.out)], [("FILE", args.file)])
    with tempfile.TemporaryDirectory(prefix="lmm-export-") as folder:
        source = replay_to_bvh(args.file, folder, args.controller) if is_session(args.file) else args.file
        anim = load_motion(source)
    known = MOTION_UNIT_M if str(source).lower().endswith((".glb", ".gltf", ".fbx")) else None   # read in cm
    scale = args.unit_scale or known or guess_unit_scale(anim.names, anim.parents, anim.offsets) or 1.0
    save_glb(args.out, anim, scale, mesh=args.mesh)
    print(f"{args.file}: {anim.n_joints} joints, {anim.n_frames} frames at {anim.fps:g} fps "
          f"({scale:g} m per file unit) -> {args.out}")
    return 0

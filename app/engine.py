"""Start-up of the studio's engine side: the options, the database, the controllers and the session
(no GUI)."""
from __future__ import annotations

import sys
from dataclasses import dataclass
from typing import Callable

from lmm.factory import make_controllers

from .session import Session


@dataclass
class StudioOptions:
    manifest: str | None = None
    weights: str | None = None
    layout: str | None = None
    input: str | None = None
    frames: int | None = None
    screenshot: str | None = None
    width: int = 1600
    height: int = 900
    lmm: bool = True
    script: str | None = None
    dump_state: str | None = None
    fixed_step: bool = False
    gamepads: bool = True
    save_layout: bool = True
    write_layouts: str | None = None
    samples: int = -1
    render_scale: float = 1.0
    readback_3d: bool = False    # read the 3D view back into a raw texture (see app.gl_texture)
    cache: str | None = None
    physics: bool = True
    tuning: str | None = None            # a tuning preset file to start from
    tuning_preset: dict | None = None    # its JSON object, already read (the command line checks it first)
    ui_antialiasing: str = "auto"        # "auto" (off on software GL), "on" or "off"
    open: str | None = None              # a session file to reopen (app.review)


def load_session(opts: StudioOptions, report_error: Callable[[str, str], None]) -> tuple[Session, str | None]:
    """The session for ``opts`` and why LMM is not running (None when it is). A broken manifest opens
    the default database; a problem with the LMM weights is reported and the studio runs MM only."""
    from lmm.data.build import load_or_build
    from lmm.features import build_features

    try:
        db, _ = load_or_build(opts.manifest, cache_dir=opts.cache)
    except Exception as e:  # a broken manifest or BVH file: say so and open the default data
        if opts.manifest is None:
            raise
        report_error("Database", f"{e} - opened the default database instead")
        opts.manifest = None
        db, _ = load_or_build(None, cache_dir=opts.cache)
    features = build_features(db)
    tuning = _start_tuning(opts, features, report_error)
    # the database's own channels and tags get entries (their sliders set them); the controllers only read
    tuning.name_database_entries({ch.name: float(w) for ch, w in zip(features.layout, features.weights)},
                                 db.tag_names)
    controllers, problems = make_controllers(db, features, tuning, weights=opts.weights, with_lmm=opts.lmm)
    lmm_problem = None
    for p, serious in problems:
        lmm_problem = p
        if serious:
            report_error("Learned motion matching", p)
        else:
            print(f"lmm-studio: {p}", file=sys.stderr)
    if not opts.lmm:
        lmm_problem = "LMM is off (--no-lmm)"
    session = Session(db, features, tuning, controllers)
    session.report = report_error   # what the ticks find (an unusable pose), once, on the GUI thread
    session.manifest = opts.manifest
    session.start_latent_table(opts.weights)
    if opts.physics:
        session.start_ragdolls()
    else:
        session.physics_status = "physics is off (--no-physics)"
    return session, lmm_problem


def _start_tuning(opts: StudioOptions, features, report_error: Callable[[str, str], None]):
    """The tuning the studio starts with: the defaults, or ``opts.tuning``'s preset. A preset that names a
    feature channel this database lacks (known only now) is reported and the defaults are used."""
    from lmm.tuning import Tuning, TuningError

    if opts.tuning is None:
        return Tuning()
    try:
        preset = opts.tuning_preset if opts.tuning_preset is not None else Tuning.read_preset(opts.tuning)
        return Tuning.from_preset(preset, opts.tuning, channels=[ch.name for ch in features.layout])
    except TuningError as e:
        report_error("Tuning preset", f"{e} - started with the default tuning")
        return Tuning()

"""The one place controllers are built: ``run``, ``eval``, ``bench`` and the studio session all call
:func:`make_controller` / :func:`make_controllers`, so a controller is never assembled two ways."""
from __future__ import annotations

from pathlib import Path

from lmm.controller import Controller
from lmm.tuning import Tuning

CONTROLLER_NAMES = ("mm", "lmm")


def make_controller(name: str, db, features, tuning: Tuning | None = None, weights=None,
                    debug_comparison: bool = True) -> Controller:
    """A controller by name: ``"mm"`` (motion matching) or ``"lmm"`` (learned motion matching with the
    shipped networks, or those in ``weights``; ``debug_comparison``: also run the exact nearest-neighbour
    search beside the projector for the debugger, which never changes the motion). Raises ``ValueError`` for another name and
    :class:`lmm.data.weights.WeightsError` (or ``OSError``) for networks that cannot be used."""
    tuning = tuning if tuning is not None else Tuning()
    if name == "mm":
        from lmm.mm import MotionMatchingController

        return MotionMatchingController(db, features, tuning)
    if name == "lmm":
        from lmm.learned import LearnedMotionMatchingController, load_default_networks

        networks = load_default_networks(db, features, path=weights)
        return LearnedMotionMatchingController(db, features, tuning, networks=networks,
                                               compare_with_search=debug_comparison)
    raise ValueError(f"unknown controller {name!r} (choose one of {', '.join(CONTROLLER_NAMES)})")


def default_weights_missing() -> bool:
    """True when no networks were shipped or trained yet (worth a status line, not an error dialog)."""
    from lmm import learned

    return not Path(learned.DEFAULT_WEIGHTS).exists()


def make_controllers(db, features, tuning: Tuning, weights=None, with_lmm: bool = True):
    """``({name: controller}, [(problem, serious)])``: MM always; LMM when asked for and loadable
    (else a problem says why and the caller runs MM only). ``serious`` is False when the default
    networks simply are not there (a status line), True for a broken or mismatched file."""
    controllers: dict[str, Controller] = {"mm": make_controller("mm", db, features, tuning)}
    problems: list[tuple[str, bool]] = []
    if with_lmm:
        try:
            controllers["lmm"] = make_controller("lmm", db, features, tuning, weights)
        except Exception as e:  # a bad weights file, a layout mismatch: reported, MM keeps running
            quiet = weights is None and default_weights_missing()
            problems.append((f"Learned motion matching is off: {e}", not quiet))
    return controllers, problems

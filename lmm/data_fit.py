"""Does a database fit what is asked of it? Two mistakes that otherwise pass in silence (issue 35, item 9):

* **speeds**: the tuning asks for run or walk speeds the database holds no motion for. Matching then
  picks the fastest frames there are and the character skates (a 0-0.75 m/s database under the default
  3.5 m/s run gave 306 cm/s of foot skating). A speed counts as covered up to :data:`SPEED_MARGIN` times
  the 99th percentile of the simulation bone's ground speed over all frames (the shipped set's p99 is
  3.47 m/s against the default 3.5 m/s run);
* **bone roles**: the manifest's ``bones`` name the wrong joints (the ankles as toes, a knee as the
  foot). Judged on the database's own poses, not the rest pose (LAFAN1's rest pose lies along x): the
  toe role should not sit above the foot role, and the lower of the two toes should be the lowest
  joint, within :data:`LOWEST_TOLERANCE_M`, in most frames.

:func:`fit_warnings` gives each problem as one line (build-db and run print them as ``warning:``);
:class:`DataFit` checks one database again and again as the tuning changes, and its ``status_text`` is the
short form the studio's menu bar shows (the whole lines in its tooltip).
"""
from __future__ import annotations

import numpy as np

from lmm.kinematics import forward_kinematics_of

#: the tuning fields that ask for a root speed (m/s)
SPEED_FIELDS = ("run_forward_speed_m_s", "run_sideways_speed_m_s", "run_backwards_speed_m_s",
                "walk_forward_speed_m_s", "walk_sideways_speed_m_s", "walk_backwards_speed_m_s")
SPEED_PERCENTILE = 99.0
SPEED_MARGIN = 1.25          # asked speed / database p99 beyond which the data does not cover it
ROLE_SAMPLE_FRAMES = 2000    # frames the role checks pose (spread over the database)
LOWEST_TOLERANCE_M = 0.03    # the toes may be this far above the lowest joint (a toe tip, a heel)
ROLE_FRACTION = 0.5          # a role check fails when it fails in more than this fraction of frames


def root_speed_percentile(db, q: float = SPEED_PERCENTILE) -> float:
    """The ``q``-th percentile of the simulation bone's ground speed over the database's frames (m/s)."""
    v = np.asarray(db.velocities[:, 0], np.float64)
    return float(np.percentile(np.hypot(v[:, 0], v[:, 2]), q)) if len(v) else 0.0


def speeds_beyond(tuning, p99_m_s: float) -> list[tuple[str, float]]:
    """The tuning's speed fields (name, m/s) beyond :data:`SPEED_MARGIN` times a database's ``p99_m_s``."""
    limit = SPEED_MARGIN * p99_m_s
    return [(name, float(getattr(tuning, name))) for name in SPEED_FIELDS if float(getattr(tuning, name)) > limit]


def _speed_lines(name: str, p99_m_s: float, beyond: list[tuple[str, float]]) -> list[str]:
    if not beyond:
        return []
    asked = ", ".join(f"{field.removesuffix('_m_s')} {v:g}" for field, v in beyond)
    return [f"the tuning asks for speeds the database {name} does not cover ({asked} m/s; its root speed p99 is "
            f"{p99_m_s:.2f} m/s): the character will skate at those speeds; lower them in the tuning or add "
            f"faster motion"]


def speed_warnings(db, tuning) -> list[str]:
    """One line when the tuning asks for speeds beyond what the database covers (see the module doc)."""
    p99 = root_speed_percentile(db)
    return _speed_lines(db.name, p99, speeds_beyond(tuning, p99))


def _sample_heights(db, bones) -> np.ndarray:
    """World heights (m) ``(n, len(bones))`` of ``bones`` at up to ROLE_SAMPLE_FRAMES frames."""
    frames = np.unique(np.linspace(0, db.n_frames - 1, min(db.n_frames, ROLE_SAMPLE_FRAMES)).astype(np.int64))
    _, pos = forward_kinematics_of(db.rotations, db.positions, db.parents, bones, frames)
    return pos[..., 1]


def role_warnings(db) -> list[str]:
    """Lines for bone roles that look wrong on the database's poses (see the module doc)."""
    roles = db.bone_roles
    needed = ("left_foot", "right_foot", "left_toe", "right_toe")
    if db.n_frames == 0 or not all(r in roles for r in needed):
        return []
    index = {r: db.names.index(roles[r]) for r in needed}
    bodies = list(range(1, db.n_bones))          # every joint but the simulation bone
    h = _sample_heights(db, bodies)
    column = {r: bodies.index(i) for r, i in index.items()}
    out = []
    for side in ("left", "right"):
        foot, toe = roles[f"{side}_foot"], roles[f"{side}_toe"]
        if foot == toe:
            out.append(f"bone roles: {side}_foot and {side}_toe are the same bone {foot}")
            continue
        above = h[:, column[f"{side}_toe"]] > h[:, column[f"{side}_foot"]]
        if above.mean() > ROLE_FRACTION:
            out.append(f"bone roles: {side}_toe ({toe}) is above {side}_foot ({foot}) in {above.mean():.0%} of the "
                       f"frames: do the manifest's bones name the right joints?")
    toes = np.minimum(h[:, column["left_toe"]], h[:, column["right_toe"]])
    lowest = h.argmin(axis=1)
    high = toes - h.min(axis=1) > LOWEST_TOLERANCE_M
    if high.mean() > ROLE_FRACTION:
        usual = db.names[bodies[int(np.bincount(lowest[high]).argmax())]]
        gap = float(np.median((toes - h.min(axis=1))[high])) * 100.0
        out.append(f"bone roles: the toes ({roles['left_toe']}, {roles['right_toe']}) are not the lowest joints in "
                   f"{high.mean():.0%} of the frames ({usual} is, {gap:.0f} cm lower): should {usual} be a toe?")
    return out


class DataFit:
    """The checks of one database for a caller that asks again as the tuning changes (the studio's status
    line, every frame): what poses or sorts the database (the speed percentile, the role lines) is worked
    out once, after which a check is six comparisons."""

    def __init__(self, db):
        self.name = db.name
        self.speed_p99_m_s = root_speed_percentile(db)
        self.roles = role_warnings(db)

    def warnings(self, tuning) -> list[str]:
        """Every line of :func:`speed_warnings` and :func:`role_warnings`."""
        return _speed_lines(self.name, self.speed_p99_m_s, speeds_beyond(tuning, self.speed_p99_m_s)) + self.roles

    def status_text(self, tuning) -> str:
        """The short form a status line has room for: empty when the database fits, else
        ``data: ...`` with the fastest speed asked against the data's p99 and how many role lines there are
        (:meth:`warnings` has the whole lines)."""
        parts = []
        beyond = speeds_beyond(tuning, self.speed_p99_m_s)
        if beyond:
            parts.append(f"the tuning asks for up to {max(v for _, v in beyond):g} m/s, the database's root speed "
                         f"p99 is {self.speed_p99_m_s:.2f} m/s")
        if self.roles:
            parts.append(f"{len(self.roles)} bone role problem{'s' if len(self.roles) > 1 else ''}")
        return "data: " + "; ".join(parts) if parts else ""


def fit_warnings(db, tuning) -> list[str]:
    """Every line of :func:`speed_warnings` and :func:`role_warnings`."""
    return DataFit(db).warnings(tuning)


def status_text(db, tuning) -> str:
    """:meth:`DataFit.status_text` of ``db``."""
    return DataFit(db).status_text(tuning)


__all__ = ["DataFit", "SPEED_FIELDS", "fit_warnings", "role_warnings", "root_speed_percentile", "speed_warnings",
           "speeds_beyond", "status_text"]

"""Physics of a motion: a MuJoCo body for any skeleton and what a real body would need to move like it.

* :mod:`lmm.physics.body`: a MuJoCo model generated from a skeleton (capsules from bone lengths, masses
  from segment fractions, a free root, ball joints, foot boxes that can stand) and the pose -> ``qpos`` map;
* :mod:`lmm.physics.plausibility`: inverse dynamics per frame, ground contact forces inside friction
  cones, the root residual force and torque, ground penetration and contact sliding;
* :mod:`lmm.physics.env`: an imitation environment around the body (observation, PD-target actions,
  reset from database frames, adversarial-imitation reward terms named, not trained).

``mujoco`` is optional (the ``physics`` extra of pyproject.toml): nothing here imports it at module level,
and :func:`require_mujoco` raises :class:`PhysicsUnavailable` (one line: how to install it) when absent.
"""
from __future__ import annotations

from lmm.errors import InputError

INSTALL_HINT = "pip install -e '.[physics]' (or: pip install 'mujoco>=3.1')"


class PhysicsUnavailable(InputError):
    """The optional ``mujoco`` package is not installed; the message says how to install it."""


def require_mujoco(purpose: str = "physics"):
    """The ``mujoco`` module, or :class:`PhysicsUnavailable` naming what needs it and how to install it."""
    try:
        import mujoco
    except ImportError as e:
        why = "is not installed" if isinstance(e, ModuleNotFoundError) and e.name in (None, "mujoco") \
            else f"failed to import ({e})"
        raise PhysicsUnavailable(f"{purpose} needs mujoco, which {why}: {INSTALL_HINT}") from None
    return mujoco


def mujoco_available() -> bool:
    """True when ``mujoco`` imports (the studio's physics panel and ``eval``'s physics keys use it)."""
    try:
        require_mujoco()
    except PhysicsUnavailable:
        return False
    return True

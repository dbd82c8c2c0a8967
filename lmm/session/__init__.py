"""Sessions: a run kept in one SQLite file, reopened, replayed bit for bit, branched and compared.

* :mod:`lmm.session.schema`: the file's tables, limits and the pose fingerprint (the format, documented
  for other programs in the README's "Sessions" section);
* :mod:`lmm.session.actions`: event kinds (tuning changes, resets, teleports, studio commands), how one is
  checked and how it acts; the ``--events`` file format;
* :mod:`lmm.session.writer`: :class:`SessionWriter`, crash-safe writing as the run goes;
* :mod:`lmm.session.reader`: :func:`open_session`, every part checked before a replay;
* :mod:`lmm.session.player`: :class:`SessionRecorder` (the hooks ``run`` uses) and :class:`SessionPlayer`
  (replay and branch, fingerprints checked);
* :mod:`lmm.session.trace`: one row per tick and controller (``lmm-studio trace``);
* :mod:`lmm.session.ab`: two arms of one session in lockstep (``lmm-studio ab``).

Engine only: the studio and the CLI (``app/``) build on it. The studio's session writes one the way ``run``
does: ``SessionWriter(path, fps=..., db=..., manifest=..., controllers=session.controllers, tuning=...,
start=...)``, then ``begin_tick(tick, input)`` / ``end_tick(tick, poses)`` around each
:func:`lmm.runner.step_controllers`; the tuning's change events are recorded by the writer itself, and each
:class:`app.command_registry.CommandRun` becomes ``writer.event("reset" | "teleport" | "command", payload)``.
"""
from lmm.session.schema import SUFFIX, SessionError, pose_fingerprint

__all__ = ["SUFFIX", "SessionError", "pose_fingerprint"]

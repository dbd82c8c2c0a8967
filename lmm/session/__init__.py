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
* :mod:`lmm.session.ab`: two arms of one session in lockstep (``lmm-studio ab``);
* :mod:`lmm.session.checkpoint` and :mod:`lmm.session.seek`: controller-state checkpoints and
  :class:`SessionSeeker`, any tick of a session re-simulated from the nearest one (``lmm-studio --open``);
* :mod:`lmm.session.why_not`: one frame's place in a tick's search, and the search re-ranked under
  another tuning (what if).

Engine only: the studio and the CLI (``app/``) build on it. The studio writes one for every recording
(:mod:`app.session_log`): from its last reset, ``SessionWriter(path, ..., start_tuning=..., recording_from=T)``
and ``write_past(...)`` for the ticks before the recording, then ``begin_tick(tick, input)`` /
``end_tick(tick, poses)`` around each :func:`lmm.runner.step_controllers`; the tuning's change events are
recorded by the writer itself, resets and the studio's motion-changing commands with ``writer.event``.
"""
from lmm.session.schema import SUFFIX, SessionError, pose_fingerprint

__all__ = ["SUFFIX", "SessionError", "pose_fingerprint"]

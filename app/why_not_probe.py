"""Why not that frame, and what if: the studio's questions about the search of the shown tick.

Both need the inspected controller as it was just before the shown tick's search, which only a reopened
session can give back (:meth:`lmm.session.seek.SessionSeeker.before`: re-simulated from a checkpoint, the
seeker put back after); a live studio is asked to open a session (the studio writes one beside every
recording). :meth:`TickProbe.why_not` explains one frame beside the chosen one and the continuing pose
(:func:`lmm.session.why_not.explain_frame`); :meth:`TickProbe.what_if` keeps a scratch tuning (the
session's tuning at the shown tick plus the user's edits) and re-ranks the tick's search under it
(:func:`lmm.session.why_not.what_if`: nothing re-simulated). The Search Candidates panel shows both.
"""
from __future__ import annotations

from lmm.errors import InputError


class ProbeUnavailable(InputError):
    """The shown tick cannot be asked (live, no search, not motion matching): the one line says why."""


class TickProbe:
    def __init__(self, studio):
        self.studio = studio
        self.changes: list[tuple[str, object, str | None]] = []   # the scratch tuning's edits, in order

    def shown_any(self):
        """``(seeker, step, name, snap)``: the reopened session's seeker, the step that made the shown tick
        (history tick ``n`` is the pose after ``n`` steps), the inspected controller and its snapshot."""
        s = self.studio
        history = s.session.history
        seeker = getattr(history, "seeker", None)
        if seeker is None or not s.playback.reviewing:
            raise ProbeUnavailable("why not / what if ask a reopened session: open one (File > Open session; "
                                   "the studio writes one beside every recording)")
        tick = s.playback.displayed_tick()
        if tick is None:
            raise ProbeUnavailable("no tick is shown")
        return seeker, int(tick.tick) - 1, s.inspected, tick.snapshots[s.inspected]

    def _shown(self):
        """:meth:`shown_any` of a controller with a ranked search (motion matching)."""
        seeker, step, name, snap = self.shown_any()
        if not hasattr(seeker.controllers.get(name), "tag_groups"):
            raise ProbeUnavailable(f"{name} has no ranked search to ask (inspect the motion matching controller)")
        return seeker, step, name, snap

    def why_not(self, frame: int) -> dict:
        """``{tick, controller, note, asked, chosen, continuing}``: the explanations
        (:func:`lmm.session.why_not.explain_frame`) of ``frame``, of the frame the shown tick's search chose
        and of the pose that was playing (the continuing pose, no transition cost) against the tick's query."""
        from lmm.session.why_not import explain_frame

        seeker, step, name, snap = self._shown()
        query = snap.query
        with seeker.before(step) as controllers:
            c = controllers[name]
            playing = int(c.frame)
            out = {"tick": step + 1, "controller": name, "asked": explain_frame(c, query, frame),
                   "chosen": explain_frame(c, query, chosen_frame(snap)),
                   "continuing": explain_frame(c, query, playing)}
        out["note"] = "" if snap.searched else ("no search this tick: the costs are what this tick's query "
                                                "would give (the frames shown are the last search's)")
        return out

    def continuing(self) -> dict | None:
        """The continuing pose at the shown tick's search (:func:`lmm.session.why_not.explain_frame` of the
        frame that was playing), or None where it cannot be asked (live, LMM, no search this tick)."""
        from lmm.session.why_not import explain_frame

        try:
            seeker, step, name, snap = self._shown()
        except ProbeUnavailable:
            return None
        if not snap.searched:
            return None
        with seeker.before(step) as controllers:
            c = controllers[name]
            return explain_frame(c, snap.query, int(c.frame))

    def scratch(self, base):
        """The scratch tuning: a copy of ``base`` (the session's at the shown tick) with the edits applied."""
        tuning = base.copy()
        for field, value, channel in self.changes:
            tuning.set(field, value, channel)
        return tuning

    def edit(self, field: str, value, channel: str | None = None) -> None:
        """One more edit of the scratch tuning (checked now: a bad field or value is refused in one line)."""
        self.scratch(self.studio.session.tuning).set(field, value, channel)
        self.changes.append((field, value, channel))

    def clear(self) -> None:
        self.changes.clear()

    def what_if(self) -> dict:
        """``{tick, controller, result, changes}``: the shown tick's search re-ranked under the scratch tuning
        (``result``: a ``lmm.search_ranking.SearchResult``), and the scratch tuning's edits."""
        from lmm.session.why_not import what_if

        seeker, step, name, snap = self._shown()
        with seeker.before(step) as controllers:
            result = what_if(controllers[name], snap.query, self.scratch(seeker.tuning))
        return {"tick": step + 1, "controller": name, "result": result, "changes": list(self.changes),
                "searched": bool(snap.searched)}


def chosen_frame(snap) -> int:
    """The frame the tick's search chose: its best candidate (the played frame is one on when it jumped)."""
    cands = snap.candidates
    return int(cands.frames[0]) if snap.searched and cands is not None and len(cands.frames) else int(snap.matched_frame)


def explanation_lines(why: dict, channel_names) -> list[str]:
    """The why-not text (pure, for tests): the asked frame's rule or its costs beside the chosen frame's and
    the continuing pose's, one row each: total = channels + bias + transition."""
    lines = [f"tick {why['tick']} ({why['controller']}): why not frame {why['asked']['frame']}?"]
    if why.get("note"):
        lines.append(why["note"])
    asked = why["asked"]
    if asked["excluded"]:
        lines.append(f"excluded: {asked['excluded']}")
    rows = [("asked", asked), ("chosen", why["chosen"]), ("continuing", why["continuing"])]
    for label, e in rows:
        if e["excluded"]:
            if label != "asked":
                lines.append(f"{label:<10} {e['frame']:>6}  excluded: {e['excluded']}")
            continue
        channels = "  ".join(f"{n}={e['channels'][n]:.3f}" for n in channel_names if n in e["channels"])
        lines.append(f"{label:<10} {e['frame']:>6}  total {e['total']:.3f} = features {e['feature_cost']:.3f}"
                     f" + bias {e['bias']:.3f} + transition {e['transition_cost']:.3f}   {channels}")
    return lines

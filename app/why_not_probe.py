"""Why not that frame, and what if: the studio's questions about the search of the shown tick.

Both need the inspected controller as it was just before the shown tick's search. A reopened session gives
it back exactly (:meth:`lmm.session.seek.SessionSeeker.before`: re-simulated from a checkpoint, the seeker
put back after). A paused live studio has stepped on, but what a search reads of its controller besides the
tuning is two numbers the rewind history holds (:func:`live_before`): the frame that was playing (the tick
before's) and how long the stick had been released (the idle set); the live tuning must be the tick's (a
tuning change made after it is refused in one line). :meth:`TickProbe.why_not` explains one frame beside
the chosen one and the continuing pose (:func:`lmm.session.why_not.explain_frame`); :meth:`TickProbe.what_if`
keeps a scratch tuning (the tuning at the shown tick plus the user's edits) and re-ranks the tick's search
under it (:func:`lmm.session.why_not.what_if`: nothing re-simulated). The Search Candidates panel shows both.
"""
from __future__ import annotations

from contextlib import contextmanager

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
        """``(before, tuning, step, name, snap)`` of a controller with a ranked search (motion matching):
        ``before(step)`` is a context manager giving the controllers as they were just before that step
        (the reopened session's seeker's, or the paused live studio's: :func:`live_before`), ``tuning``
        the tuning they searched with."""
        s = self.studio
        if not s.playback.reviewing:
            if not s.playback.paused:
                raise ProbeUnavailable("why not / what if ask a reopened session or the paused studio: pause "
                                       "(Space), or open one (File > Open session)")
            tick = s.playback.displayed_tick()
            if tick is None or s.inspected not in tick.snapshots:
                raise ProbeUnavailable("no tick is shown")
            name, session = s.inspected, s.session
            before, tuning, snap = (lambda step: live_before(session, step + 1, name)), session.tuning, \
                tick.snapshots[name]
            step, controller = int(tick.tick) - 1, session.controllers.get(name)
        else:
            seeker, step, name, snap = self.shown_any()
            before, tuning, controller = (lambda step: session_before(seeker, step, name)), seeker.tuning, \
                seeker.controllers.get(name)
        if not hasattr(controller, "tag_groups"):
            raise ProbeUnavailable(f"{name} has no ranked search to ask (inspect the motion matching controller)")
        return before, tuning, step, name, snap

    def why_not(self, frame: int) -> dict:
        """``{tick, controller, note, asked, chosen, continuing}``: the explanations
        (:func:`lmm.session.why_not.explain_frame`) of ``frame``, of the frame the shown tick's search chose
        and of the pose that was playing (the continuing pose, no transition cost) against the tick's query."""
        from lmm.session.why_not import explain_frame

        before, _, step, name, snap = self._shown()
        query = snap.query
        with before(step) as controllers:
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
            before, _, step, name, snap = self._shown()
        except ProbeUnavailable:
            return None
        if not snap.searched:
            return None
        with before(step) as controllers:
            c = controllers[name]
            return explain_frame(c, snap.query, int(c.frame))

    def scratch(self, base):
        """The scratch tuning: a copy of ``base`` (the tuning at the shown tick) with the edits applied."""
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

        before, tuning, step, name, snap = self._shown()
        with before(step) as controllers:
            result = what_if(controllers[name], snap.query, self.scratch(tuning))
        return {"tick": step + 1, "controller": name, "result": result, "changes": list(self.changes),
                "searched": bool(snap.searched)}


@contextmanager
def session_before(seeker, step: int, name: str):
    """:meth:`lmm.session.seek.SessionSeeker.before` ``step``, with the stick release of controller ``name``
    counted for the step's input: the step counts it before it searches, so the search saw one tick more
    than the state before the step holds (at the idle delay, the idle set one tick earlier)."""
    with seeker.before(step) as controllers:
        c = controllers[name]
        released = not stick_pushed(seeker.input_at(step), c.tuning)
        c.stick_released_s = c.stick_released_s + seeker.dt if released else 0.0
        yield controllers


@contextmanager
def live_before(session, tick: int, name: str):
    """For the body of a ``with``: the live controllers (an :class:`app.session.Session`'s, paused) with
    ``name`` put as it was at history tick ``tick``'s search: playing the frame the tick before played,
    the stick released as long as the history's inputs say; put back as it was afterwards. Raises
    :class:`ProbeUnavailable` when the history cannot say (the tick before has left it) or the tuning
    changed after that tick (the controllers search with the tuning of now)."""
    from lmm.session.checkpoint import ControllerState

    history, log = session.history, session.log
    previous = history.get(tick - 1)
    if previous is None or name not in previous.snapshots:
        raise ProbeUnavailable(f"tick {tick - 1}, the one before the shown tick, is not in the rewind history: "
                               "ask a later tick")
    step = log.tick - 1 - (session.tick - tick)      # the log's number of the step that made ``tick``
    later = [p["field"] + (f".{p['channel']}" if p.get("channel") else "")
             for t, kind, p in log.events if kind == "tuning" and t > step]
    if later:
        raise ProbeUnavailable(f"the tuning changed after tick {tick} ({', '.join(later[:3])}"
                               f"{', ...' if len(later) > 3 else ''}): ask a tick after the change, or the session "
                               "(a recording writes one)")
    c = session.controllers[name]
    state = ControllerState(c)
    try:
        c.frame = int(previous.snapshots[name].matched_frame)
        c.stick_released_s = stick_released_s(history, tick, c.tuning, session.dt)
        yield session.controllers
    finally:
        state.restore(c)


def stick_released_s(history, tick: int, tuning, dt: float) -> float:
    """A controller's ``stick_released_s`` at history tick ``tick``'s search: ``dt`` added once per tick
    (as the controller adds it) since the left stick was last outside its deadzone, counted back through the
    history's inputs to that tick or to the reset that started the history; exact unless the stick was
    released before the history's oldest tick (then it is longer than the history, far past the idle delay,
    and only that matters to a search)."""
    released, t = 0, tick
    while True:
        held = history.get(t)
        inp = None if held is None else held.extra.get("input")
        if inp is None or stick_pushed(inp, tuning):
            break
        released, t = released + 1, t - 1
    seconds = 0.0
    for _ in range(released):
        seconds = seconds + dt
    return seconds


def stick_pushed(inp, tuning) -> bool:
    """Whether the left stick of ``inp`` is outside its deadzone (a controller then counts no release)."""
    from lmm.trajectory import stick_world

    return any(stick_world(inp.left_x, inp.left_y, tuning.stick_deadzone, inp.camera_azimuth))


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

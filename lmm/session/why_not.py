"""Why this pose, why not that one: one database frame's place in a motion matching search.

:func:`explain_frame` takes an MM controller as it was just before the tick that searched (a
:class:`lmm.session.seek.SessionSeeker` at that tick puts it there) and the tick's normalised query, and
says for any frame either the rule that kept it out of the search (end of its range, an excluded tag or the
idle set, the window around the playing frame) or its cost: per feature channel, the tag bias and the
transition cost, adding up to the total the search ranked it by. The playing frame is the continuing pose,
with no transition cost. :func:`what_if` re-ranks the same search under a scratch tuning.
"""
from __future__ import annotations

import numpy as np

from lmm.search_ranking import channel_costs, frame_costs


def explain_frame(controller, query_norm: np.ndarray, frame: int) -> dict:
    """``{frame, continuing, excluded, channels, feature_cost, bias, transition_cost, total}``: ``excluded``
    is the rule's one line ("" when the frame competes, and then the costs are filled)."""
    db, tun = controller.db, controller.tuning
    frame, current = int(frame), int(controller.frame)
    out = {"frame": frame, "continuing": frame == current, "excluded": "", "channels": {},
           "feature_cost": float("nan"), "bias": float("nan"), "transition_cost": float("nan"),
           "total": float("nan")}
    if not 0 <= frame < db.n_frames:
        out["excluded"] = f"frame {frame} is outside the database's {db.n_frames} frames"
        return out
    if not controller.candidate_mask()[frame]:
        out["excluded"] = (f"end of its range: within the last {max(int(tun.exclude_range_end_frames), 1)} "
                           f"frames (exclude_range_end_frames)")
        return out
    groups = controller.tag_groups()
    bias = next((b for b, m in groups if m[frame]), None)
    if bias is None:
        tags = db.tags_of(frame)
        out["excluded"] = ("not in the idle set (the stick is released)" if controller.idle_set_active()
                           else "an excluded tag" + (f" ({', '.join(tags)})" if tags else "") + " (tag_excluded)")
        return out
    window = int(tun.exclude_current_window_frames)
    if current >= 0 and frame != current and abs(frame - current) <= window:
        out["excluded"] = (f"within {window} frames of the playing frame {current} "
                           f"(exclude_current_window_frames)")
        return out
    features = controller.features
    q = np.asarray(query_norm, dtype=np.float32)
    cost = float(frame_costs(features.normalized[frame:frame + 1], q)[0])
    per = channel_costs(features.normalized, np.array([frame]), q, features.slices)[0]
    tc = 0.0 if frame == current else float(np.float32(tun.transition_cost))
    out.update(channels={n: float(c) for n, c in zip(features.names, per)}, feature_cost=cost,
               bias=float(bias), transition_cost=tc,
               total=float(np.float32(cost) + np.float32(tc) + np.float32(bias)))
    return out


def what_if(controller, query_norm: np.ndarray, scratch, top_k: int | None = None):
    """The ranked candidates (of an MM controller) (``lmm.search_ranking.SearchResult``: frames, costs, bias, channel costs) the
    same search would give under ``scratch`` (a :class:`lmm.tuning.Tuning`: other feature weights, tag
    biases or exclusions, transition cost, windows), from the controller as the search found it; nothing is
    re-simulated and the controller is left as it was. New feature weights renormalise the query (from its
    raw values: a channel whose old weight was 0 comes back as its mean)."""
    from lmm.session.checkpoint import ControllerState

    state = ControllerState(controller)
    features = controller.features
    raw = features.denormalize(np.asarray(query_norm, dtype=np.float32))
    try:
        vars(controller)["tuning"] = scratch          # what the search reads (not announced: nothing else changes)
        controller._tag_tuning = None                  # its tag groups come from the scratch tuning
        controller._weights_stale = True
        q = features.normalize(raw) if controller._apply_feature_weights() else query_norm
        return controller.search(q, top_k=int(scratch.top_k) if top_k is None else int(top_k))
    finally:
        state.restore(controller)

"""One row per tick and controller of a session, for pandas or any tool (``lmm-studio trace``).

The session is replayed (:class:`lmm.session.player.SessionPlayer`, fingerprints checked, LMM's exact
nearest-neighbour search on) and each tick's :class:`lmm.controller.DebugSnapshot` becomes a row. Columns,
in order (units: metres, seconds, m/s; costs are squared distances of normalised, weighted features):

* ``tick``, ``time_s`` (the time at the end of the tick: ``(tick + 1) * dt``), ``controller``;
* the input: ``left_x``, ``left_y``, ``right_x``, ``right_y``, ``walk``, ``strafe``, ``camera_azimuth``;
* ``frame``: the database frame played (MM) or the last projected frame the state jumped to, advanced by the
  frames played since (LMM, see :mod:`lmm.learned`); ``clip`` its range's
  name, ``tags`` the range's tags joined by ``|``;
* ``searched`` (a search / projection ran), ``forced_search``, ``transitioned`` (MM: the played frame jumped; LMM: a projector
  jump),
  ``best_cost`` (the last search's best), ``current_cost`` (the played pose against this tick's query) and
  ``cost_<channel>`` for each feature channel (``current_cost`` split by channel);
* LMM only (else -1 / empty): ``nn_frame``, ``nn_cost`` (the exact nearest frame to the query and its cost),
  ``projected_frame``, ``projected_cost`` (the projector's features' nearest frame and their cost);
* ``root_x``, ``root_y``, ``root_z``: the character root (bone 0, world); ``root_vx``, ``root_vy``, ``root_vz``:
  its velocity over the tick (0 on tick 0);
* ``contact_left``, ``contact_right``: foot contacts; ``locked_left``, ``locked_right``: feet held by IK.
"""
from __future__ import annotations

import math

import numpy as np

INPUT_FIELDS = ("left_x", "left_y", "right_x", "right_y", "walk", "strafe", "camera_azimuth")


def columns(channel_names) -> list[str]:
    """The trace's columns for a database with these feature channels."""
    return (["tick", "time_s", "controller", *INPUT_FIELDS, "frame", "clip", "tags", "searched", "forced_search",
             "transitioned", "best_cost", "current_cost"] + [f"cost_{c}" for c in channel_names]
            + ["nn_frame", "nn_cost", "projected_frame", "projected_cost", "root_x", "root_y", "root_z",
               "root_vx", "root_vy", "root_vz", "contact_left", "contact_right", "locked_left", "locked_right"])


def _finite(v) -> float:
    v = float(v)
    return v if math.isfinite(v) else float("nan")


def trace_rows(player, db, features):
    """Yield one row (a list, in :func:`columns` order) per tick and controller while ``player`` replays."""
    previous = {}
    dt = player.dt
    tag_names = list(db.tag_names)
    while not player.done:
        tick = player.tick
        poses, snaps = player.step()
        for name, snap in snaps.items():
            frame = int(snap.matched_frame)
            if 0 <= frame < db.n_frames:
                r = int(db.range_index(frame))
                clip = db.range_names[r]
                tags = "|".join(t for t, on in zip(tag_names, db.frame_tags[frame]) if on) if tag_names else ""
            else:
                clip, tags = "", ""
            query, current = snap.query, snap.current_features
            channel_costs = features.channel_costs(np.asarray(query), np.asarray(current))
            root = poses[name].global_positions[0].astype(np.float64)
            velocity = (root - previous[name]) / dt if name in previous else np.zeros(3)
            previous[name] = root
            inp = snap.input
            yield ([tick, (tick + 1) * dt, name, *(getattr(inp, f) for f in INPUT_FIELDS), frame, clip, tags,
                    bool(snap.searched), bool(snap.forced_search), bool(snap.transitioned),
                    _finite(snap.best_cost), _finite(snap.current_cost)]
                   + [float(c) for c in channel_costs]
                   + [int(snap.nn_frame), _finite(snap.nn_cost), int(snap.projected_frame),
                      _finite(snap.projected_cost), *root.tolist(), *velocity.tolist(),
                      *(bool(c) for c in snap.foot_contacts), *(bool(c) for c in snap.foot_locked)])


def _cell(v) -> str:
    if isinstance(v, bool):
        return "1" if v else "0"
    if isinstance(v, float):
        return repr(v) if math.isfinite(v) else ""
    text = str(v)
    return f'"{text}"' if any(c in text for c in ',"\n') else text


def write_csv(path, header, rows) -> int:
    """Rows as CSV (floats written exactly, NaN as an empty cell), whole or not at all; the row count."""
    from lmm.data.atomic import atomic_write

    n = 0
    with atomic_write(path, "w", encoding="utf-8") as f:
        f.write(",".join(header) + "\n")
        for row in rows:
            f.write(",".join(_cell(v) for v in row) + "\n")
            n += 1
    return n


def write_parquet(path, header, rows) -> int:
    """Rows as a parquet table (needs the optional ``pyarrow``), written whole or not at all; the row count."""
    import io

    import pyarrow as pa
    import pyarrow.parquet as pq

    from lmm.data.atomic import write_bytes_atomic

    cols = [[] for _ in header]
    for row in rows:
        for c, v in zip(cols, row):
            c.append(v)
    table = pa.table({name: values for name, values in zip(header, cols)})
    buf = io.BytesIO()
    pq.write_table(table, buf)
    write_bytes_atomic(path, buf.getvalue())
    return table.num_rows

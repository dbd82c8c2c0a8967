"""The 3D view's markers: spheres, arrows and polylines gathered as arrays (a character's own apart, on
the tick worker) and drawn with one sphere, one arrow and one line renderable."""
from __future__ import annotations

import numpy as np


class Markers:
    """Spheres, arrows and polylines gathered as arrays with (count, size, colour) runs: what
    :class:`MarkerBatch` draws; a character's own markers can be gathered apart (on the tick worker,
    see :func:`character_parts`) and added to the batch in one call."""

    def __init__(self):
        self.clear()

    def clear(self) -> None:
        # each add keeps its points and one (count, size, colour) run; flush repeats the runs
        self._centers, self._sphere_runs = [], []
        self._origins, self._vectors, self._arrow_runs = [], [], []
        self._segments, self._segment_runs = [], []

    def add_spheres(self, centers, radius: float, color) -> None:
        c = np.asarray(centers, np.float64).reshape(-1, 3)
        if len(c):
            self._centers.append(c)
            self._sphere_runs.append((len(c), radius, tuple(color[:3])))

    def add_arrows(self, origins, vectors, color) -> None:
        o = np.asarray(origins, np.float64).reshape(-1, 3)
        v = np.asarray(vectors, np.float64).reshape(-1, 3)
        n = min(len(o), len(v))
        if n:
            self._origins.append(o[:n])
            self._vectors.append(v[:n])
            self._arrow_runs.append((n, 0.0, tuple(color[:3])))

    def add_polyline(self, points, color) -> None:
        p = np.asarray(points, np.float64).reshape(-1, 3)
        if len(p) >= 2:
            seg = np.empty((2 * (len(p) - 1), 3))
            seg[0::2] = p[:-1]
            seg[1::2] = p[1:]
            self._segments.append(seg)
            self._segment_runs.append((len(seg), 0.0, tuple(color[:3])))

    def compacted(self) -> "Markers":
        """The same markers with each kind's arrays joined into one (``flush`` then copies nothing)."""
        out = Markers()
        for name in ("_centers", "_origins", "_vectors", "_segments"):
            arrays = getattr(self, name)
            setattr(out, name, [np.concatenate(arrays)] if len(arrays) > 1 else list(arrays))
        out._sphere_runs, out._arrow_runs = list(self._sphere_runs), list(self._arrow_runs)
        out._segment_runs = list(self._segment_runs)
        return out

    def extend(self, other: "Markers") -> None:
        """Add every marker of ``other`` (after this one's)."""
        self._centers += other._centers
        self._sphere_runs += other._sphere_runs
        self._origins += other._origins
        self._vectors += other._vectors
        self._arrow_runs += other._arrow_runs
        self._segments += other._segments
        self._segment_runs += other._segment_runs


def _joined(arrays: list) -> np.ndarray:
    return arrays[0] if len(arrays) == 1 else np.concatenate(arrays)


class MarkerBatch(Markers):
    """Every marker of every character, gathered per frame and drawn with one sphere, one arrow and
    one line renderable (few draw calls matter on software GL, where each costs about a millisecond)."""

    def __init__(self, viewer, ctx):
        self.spheres = viewer.Spheres(ctx, radius=0.04)
        self.arrows = viewer.Arrows(ctx, shaft_radius=0.011, head_radius=0.032, head_length=0.07)
        self.lines = viewer.Lines(ctx, width_px=2.5)
        self._expanded: dict = {}
        super().__init__()

    def renderables(self):
        return [self.lines, self.spheres, self.arrows]

    def clear(self) -> None:
        super().clear()
        self._arrow_geometry = None

    def prepare_arrows(self, markers: Markers) -> Markers:
        """``markers`` compacted, with its arrows' geometry worked out for this batch's arrows (see
        ``Arrows.prepare``): safe on another thread; ``extend`` by it, and ``flush`` uses that geometry
        when no other arrow was added."""
        out = markers.compacted()
        if out._origins:
            out.arrow_geometry = (out._origins[0], self.arrows.prepare(out._origins[0], out._vectors[0]))
        return out

    def extend(self, other: Markers) -> None:
        had = bool(self._origins)
        super().extend(other)
        if other._origins:
            self._arrow_geometry = None if had else getattr(other, "arrow_geometry", None)

    def _repeat(self, runs):
        """(per-item sizes (N,), per-item colours (N, 3)) of a list of (count, size, colour) runs; the
        runs are the same from frame to frame, so their expansions are kept (never written to)."""
        key = tuple(runs)
        hit = self._expanded.get(key)
        if hit is None:
            counts = [r[0] for r in runs]
            hit = (np.repeat(np.array([r[1] for r in runs], np.float64), counts),
                   np.repeat(np.array([r[2] for r in runs], np.float64), counts, axis=0))
            # read-only: the renderables then know the same array means the same values and keep
            # the columns they wrote from it
            for a in hit:
                a.flags.writeable = False
            if len(self._expanded) > 64:
                self._expanded.clear()
            self._expanded[key] = hit
        return hit

    def flush(self) -> None:
        z3 = np.zeros((0, 3))
        if self._centers:
            radii, colors = self._repeat(self._sphere_runs)
            self.spheres.update(_joined(self._centers), radii, colors)
        else:
            self.spheres.update(z3)
        if self._origins:
            geometry = self._arrow_geometry
            if geometry is not None and (len(self._origins) != 1 or geometry[0] is not self._origins[0]):
                geometry = None     # arrows were added after the prepared ones
            self.arrows.update(_joined(self._origins), _joined(self._vectors), self._repeat(self._arrow_runs)[1],
                               prepared=None if geometry is None else geometry[1])
        else:
            self.arrows.update(z3, z3)
        if self._segments:
            self.lines.update(_joined(self._segments), mode="segments", colors=self._repeat(self._segment_runs)[1])
        else:
            self.lines.update(z3, mode="segments")

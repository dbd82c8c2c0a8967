"""Rounded cones ("capsules" whose two ends may differ in radius), drawn instanced, and their
planar ground shadow: the unit mesh and its constants; the GLSL is ``viewer/shaders/capsule.vert``
and its fragment stages, the GL objects live in ``base.Resources``.

Each instance is a segment a -> b with a radius at each end. The mesh is two caps of latitude
rings plus the side between their rims: the vertex shader places cap vertices on the sphere at
``a`` (radius ``ra``) or ``b`` (radius ``rb``) and turns the rims so the side is tangent to both
spheres, which gives one smooth surface for any pair of radii. ``a == b`` with ``ra == rb`` is a
sphere, so joints, heads and bones share one draw call.
"""
from __future__ import annotations

import numpy as np

CAPSULE_INSTANCE_FLOATS = 12   # a(3) b(3) ra(1) rb(1) color(4)
CAPSULE_INFLATE = 1.09   # exact capsules: the 16 x 4 mesh scaled by this contains the surface (facets ~4 % deep)

SHADOW_DEPTH_PULL = 1e-3   # shadows: in front of the ground, behind lines on it (2e-3)


def capsule_mesh(segments: int = 16, cap_rings: int = 4):
    """Vertices (ring cos, ring sin, lat, end) float32 and uint32 triangles of the unit rounded
    cone, counter-clockwise seen from outside."""
    phi = np.linspace(0.0, 2.0 * np.pi, segments, endpoint=False)
    ring = np.c_[np.cos(phi), np.sin(phi)]
    lat = np.linspace(0.0, 1.0, cap_rings + 1)   # pole .. rim
    rows = []
    for end in (0.0, 1.0):
        for t in lat:
            rows.append(np.c_[ring, np.full(segments, t), np.full(segments, end)])
    verts = np.concatenate(rows).astype(np.float32)
    k = np.arange(segments)
    k1 = (k + 1) % segments
    tris = []
    n_rows = 2 * (cap_rings + 1)
    # rows in order: cap a pole..rim, cap b pole..rim; connect a's rows, a's rim to b's rim, b's rows
    order = list(range(cap_rings + 1)) + list(range(2 * cap_rings + 1, cap_rings, -1))
    for r0, r1 in zip(order[:-1], order[1:]):
        base0, base1 = r0 * segments, r1 * segments
        tris.append(np.c_[base0 + k, base0 + k1, base1 + k])
        tris.append(np.c_[base0 + k1, base1 + k1, base1 + k])
    tris = np.concatenate(tris)
    assert n_rows * segments == len(verts)
    return verts, _orient(verts, tris).astype(np.uint32)


def _reference_positions(verts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and normals of the mesh for a = 0, b = +Y, ra = rb = 0.3 (same math as the shader)."""
    lat = np.where(verts[:, 3] < 0.5, -np.pi / 2 * (1 - verts[:, 2]), np.pi / 2 * (1 - verts[:, 2]))
    n = np.c_[np.cos(lat) * verts[:, 0], np.sin(lat), np.cos(lat) * verts[:, 1]]
    centre = np.c_[np.zeros(len(verts)), verts[:, 3], np.zeros(len(verts))]
    return centre + 0.3 * n, n


def _orient(verts: np.ndarray, tris: np.ndarray) -> np.ndarray:
    p, n = _reference_positions(verts)
    a, b, c = p[tris[:, 0]], p[tris[:, 1]], p[tris[:, 2]]
    face = np.cross(b - a, c - a)
    flip = (face * (n[tris[:, 0]] + n[tris[:, 1]] + n[tris[:, 2]])).sum(axis=1) < 0
    tris = tris.copy()
    tris[flip] = tris[flip][:, ::-1]
    # degenerate triangles at the poles have no orientation and cover no pixels: drop them
    keep = np.linalg.norm(face, axis=1) > 1e-12
    return tris[keep]

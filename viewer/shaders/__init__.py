"""The viewer's GLSL programs: their sources are the ``.vert``/``.frag`` files in this folder, read by
one loader.

``load_program(ctx, "capsule.vert", "capsule_exact.frag")`` reads the two stages, replaces each
``#include "name.glsl"`` line by that file (each file once per stage) and compiles them. Every
program that includes ``frame.glsl`` gets its ``Frame`` uniform block (camera and key light, the
uniforms all programs share) bound to ``FRAME_BINDING``, where ``base.Resources`` binds the one
buffer it fills each frame with ``frame_block``.
"""
from __future__ import annotations

import re
from functools import lru_cache
from importlib import resources

import moderngl
import numpy as np

FRAME_BINDING = 0
FRAME_FLOATS = 60   # the std140 layout of frame.glsl's block: 3 mat4, then 3 x (vec3|vec2, float)

_INCLUDE = re.compile(r'^[ \t]*#include[ \t]+"([^"]+)"[ \t]*$', re.MULTILINE)


@lru_cache(maxsize=None)
def _file(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


@lru_cache(maxsize=None)
def shader_source(name: str) -> str:
    """The GLSL text of the file ``name`` with its includes expanded."""
    seen: set[str] = set()

    def expand(text: str) -> str:
        def include(match: re.Match) -> str:
            part = match.group(1)
            if part in seen:
                return ""
            seen.add(part)
            return expand(_file(part)).rstrip("\n")
        return _INCLUDE.sub(include, text)

    return expand(_file(name))


def load_program(ctx: moderngl.Context, vertex: str, fragment: str) -> moderngl.Program:
    """The program of the vertex and fragment shader files ``vertex`` and ``fragment``, with its
    ``Frame`` block (if it uses it) bound to ``FRAME_BINDING``."""
    program = ctx.program(vertex_shader=shader_source(vertex), fragment_shader=shader_source(fragment))
    if "Frame" in program:
        program["Frame"].binding = FRAME_BINDING
    return program


def frame_block(view: np.ndarray, proj: np.ndarray, view_proj: np.ndarray, eye, light_dir,
                ambient: float, diffuse: float, specular: float, viewport) -> bytes:
    """The bytes of frame.glsl's ``Frame`` block (matrices row-major numpy, stored column-major)."""
    b = np.zeros(FRAME_FLOATS, dtype=np.float32)
    for k, m in enumerate((view, proj, view_proj)):
        b[16 * k:16 * k + 16] = np.asarray(m, dtype=np.float32).T.ravel()
    b[48:51] = eye
    b[51] = ambient
    b[52:55] = light_dir
    b[55] = diffuse
    b[56:58] = viewport
    b[58] = specular
    return b.tobytes()

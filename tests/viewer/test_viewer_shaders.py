"""The GLSL files and their loader: includes expanded, every stage compiles, the shared Frame block
has the layout ``frame_block`` writes, and the files ship with the package."""
import tomllib
from fnmatch import fnmatch
from pathlib import Path

import numpy as np

from viewer.shaders import FRAME_BINDING, FRAME_FLOATS, frame_block, load_program, shader_source

SHADERS = Path(__file__).resolve().parents[2] / "viewer" / "shaders"
ROOT = SHADERS.parents[1]

# every program the viewer builds (base.Resources and Ground)
PROGRAMS = [("mesh.vert", "mesh.frag"), ("line.vert", "line.frag"), ("capsule.vert", "capsule.frag"),
            ("capsule.vert", "capsule_exact.frag"), ("capsule.vert", "shadow.frag"),
            ("shadow_resolve.vert", "shadow_resolve.frag"), ("ground.vert", "ground.frag")]


def test_includes_are_expanded_once_and_version_stays_first():
    text = shader_source("capsule_exact.frag")
    assert "#include" not in text
    assert text.startswith("#version 330")
    assert text.count("uniform Frame") == 1 and text.count("vec3 shade(") == 1
    assert text.index("#extension") < text.index("uniform Frame")


def test_every_program_compiles_and_binds_the_frame_block(gl_ctx):
    stages = {name for pair in PROGRAMS for name in pair}
    assert stages == {p.name for p in SHADERS.iterdir() if p.suffix in (".vert", ".frag")}
    for vertex, fragment in PROGRAMS:
        program = load_program(gl_ctx, vertex, fragment)
        assert "Frame" in program, (vertex, fragment)
        block = program["Frame"]
        assert block.binding == FRAME_BINDING
        assert block.size == 4 * FRAME_FLOATS
        program.release()


def test_frame_block_layout():
    view, proj = np.arange(16.0).reshape(4, 4), np.arange(16.0, 32.0).reshape(4, 4)
    b = np.frombuffer(frame_block(view, proj, proj @ view, (1, 2, 3), (4, 5, 6), 0.1, 0.2, 0.3, (640, 480)),
                      dtype=np.float32)
    assert len(b) == FRAME_FLOATS
    assert np.array_equal(b[:16], view.T.ravel()) and np.array_equal(b[32:48], (proj @ view).T.ravel())
    assert np.array_equal(b[48:59], np.float32([1, 2, 3, 0.1, 4, 5, 6, 0.2, 640, 480, 0.3]))


def test_shader_files_are_package_data():
    patterns = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]["viewer"]
    for path in SHADERS.iterdir():
        if path.suffix != ".py" and path.is_file():
            assert any(fnmatch(f"shaders/{path.name}", p) for p in patterns), path.name

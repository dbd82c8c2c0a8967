"""The package import graph against the declared layers, read from the source (every ``import`` statement,
those inside functions included, so a lazy import counts like any other).

Layers of ``lmm``, lowest first; a module may import its own layer and the layers below, never above:

* ``maths``: leaf modules of plain maths and small shared types (quaternions, kinematics, springs, the
  skeleton, filters, errors, progress);
* ``data``: ``lmm.data``, file formats and the database;
* ``engine``: what a controller's tick computes with (features, search, networks, trajectory,
  inertialization, IK, tuning);
* ``runtime``: the controllers, the tick loop, the builder and the metrics the tick loop measures;
* ``analysis``: coverage, data checks, comparisons (following a reference), physics, motion search,
  sessions (record, replay, trace, A/B) and the pictures;
* ``offline``: training, evaluation and export (torch).

``viewer`` stands alone (numpy, moderngl, glfw and its own modules; it writes no files); ``app`` sits on top
and may import everything. Third-party packages where they belong: torch only in ``lmm.offline``,
dearpygui only in ``app``, moderngl and glfw only in ``viewer`` and ``app``, pillow and matplotlib only in
``lmm.reporting`` and ``app``.
"""
from __future__ import annotations

import ast
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("lmm", "viewer", "app")

LAYERS = {  # layer -> module prefixes (the longest matching prefix decides a module's layer)
    "maths": ("lmm", "lmm.errors", "lmm.quat", "lmm.kinematics", "lmm.springs", "lmm.skeleton", "lmm.filters",
              "lmm.progress", "lmm.events"),
    "data": ("lmm.data",),
    "engine": ("lmm.features", "lmm.search", "lmm.search_index", "lmm.search_ranking", "lmm.search_native",
               "lmm.nn", "lmm.trajectory", "lmm.inertialize", "lmm.ik", "lmm.tuning", "lmm.controller"),
    "runtime": ("lmm.character", "lmm.source_pose", "lmm.root_motion", "lmm.ground", "lmm.pose_rows",
                "lmm.tick_snapshot", "lmm.mm", "lmm.learned", "lmm.pose_decoding", "lmm.latents", "lmm.factory", "lmm.runner",
                "lmm.metrics", "lmm.quality", "lmm.input_from_motion"),
    "analysis": ("lmm.coverage", "lmm.checks", "lmm.compare", "lmm.data_fit", "lmm.follow", "lmm.reconstruction",
                 "lmm.physics", "lmm.motion_search", "lmm.reporting", "lmm.session"),
    "offline": ("lmm.offline",),
    "viewer": ("viewer",),
    "app": ("app",),
}
ORDER = ("maths", "data", "engine", "runtime", "analysis", "offline")
#: third-party package -> module prefixes allowed to import it
PLACES = {
    "torch": ("lmm.offline",),
    "dearpygui": ("app",),
    "moderngl": ("viewer", "app"),
    "glfw": ("viewer", "app"),
    "PIL": ("lmm.reporting", "app"),
    "matplotlib": ("lmm.reporting", "app"),
}
#: what the viewer may import besides itself and the standard library
VIEWER_THIRD_PARTY = ("numpy", "moderngl", "glfw")


def _within(module: str, prefix: str) -> bool:
    """``module`` is ``prefix`` or inside it; ``lmm`` stands for its ``__init__`` only, so a new engine
    module must be declared in a layer."""
    return module == prefix or (prefix != "lmm" and module.startswith(prefix + "."))


def layer_of(module: str) -> str:
    best = max((p for ps in LAYERS.values() for p in ps if _within(module, p)), key=len, default=None)
    if best is None:
        raise AssertionError(f"{module} is in no declared layer: add it to LAYERS in {Path(__file__).name}")
    return next(name for name, ps in LAYERS.items() if best in ps)


def module_name(path: Path) -> str:
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def imports_of(path: Path) -> list[tuple[int, str]]:
    """(line, imported module) of every import statement in the file, at any depth; ``from X import y``
    counts as X and, when X.y is a module of ours, as X.y."""
    module = module_name(path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - (node.level - 1)]
                base = ".".join(anchor + ([base] if base else []))
            out.append((node.lineno, base))
            for a in node.names:
                sub = f"{base}.{a.name}"
                if (ROOT / Path(*sub.split("."))).with_suffix(".py").is_file() or (ROOT / Path(*sub.split("."))).is_dir():
                    out.append((node.lineno, sub))
    return out


def violations() -> list[str]:
    found = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            module = module_name(path)
            where = f"{path.relative_to(ROOT)}"
            layer = layer_of(module)
            for line, target in imports_of(path):
                top = target.split(".")[0]
                if top in PLACES and not any(_within(module, p) for p in PLACES[top]):
                    found.append(f"{where}:{line}: {module} imports {target}; {top} belongs only in "
                                 f"{', '.join(PLACES[top])}")
                if top in PACKAGES:
                    theirs = layer_of(target)
                    if layer == "viewer" and theirs != "viewer":
                        found.append(f"{where}:{line}: viewer module {module} imports {target}; the viewer "
                                     f"stands alone")
                    elif layer in ORDER and theirs in ("viewer", "app"):
                        found.append(f"{where}:{line}: engine module {module} imports {target}")
                    elif layer in ORDER and ORDER.index(theirs) > ORDER.index(layer):
                        found.append(f"{where}:{line}: {module} ({layer}) imports {target} ({theirs}), "
                                     f"a layer above it")
                elif layer == "viewer" and top not in VIEWER_THIRD_PARTY and top not in sys.stdlib_module_names \
                        and top != "__future__":
                    found.append(f"{where}:{line}: viewer module {module} imports {target}; the viewer uses "
                                 f"only {', '.join(VIEWER_THIRD_PARTY)} and the standard library")
    return found


def test_every_import_follows_the_layers():
    bad = violations()
    assert not bad, "imports against the layers:\n" + "\n".join(bad)


def test_the_checker_reads_lazy_and_relative_imports(tmp_path, monkeypatch):
    """The checker itself: an import inside a function and a relative import are both seen."""
    path = ROOT / "lmm" / "data" / "jsonio.py"
    names = {t for _, t in imports_of(path)}
    assert {"lmm.data.atomic", "lmm.errors", "numpy"} <= names
    assert layer_of("lmm.data.database") == "data" and layer_of("lmm.search") == "engine"
    assert layer_of("lmm.offline.training") == "offline" and layer_of("lmm") == "maths"
    for undeclared in ("elsewhere.module", "lmm.new_module"):
        with pytest.raises(AssertionError, match="no declared layer"):
            layer_of(undeclared)


def test_a_studio_session_step_imports_nothing_offline(tmp_path):
    """What the source cannot show: running the studio's session (its lazy imports and what the imported
    packages pull in) loads no torch, plotting, GUI or GL package and nothing of ``lmm.offline``; and the
    offline evaluation, which runs the numpy networks, still loads no torch."""
    import subprocess

    forbidden = ("torch", "matplotlib", "dearpygui", "moderngl", "PIL")
    code = "\n".join([
        "import sys",
        "from lmm.data.build import load_or_build",
        "from lmm.features import build_features",
        "from lmm.factory import make_controllers",
        "from lmm.controller import InputState",
        "from lmm.tuning import Tuning",
        "from app.session import Session",
        "import lmm.nn, lmm.data.weights, lmm.latents, lmm.runner",
        "db, _ = load_or_build()",
        "f = build_features(db)",
        "t = Tuning()",
        "controllers, _ = make_controllers(db, f, t)",
        "s = Session(db, f, t, controllers)",
        f"s.start_recording({str(tmp_path / 'take.bvh')!r})",
        "[s.step(InputState(left_y=1.0)) for _ in range(10)]",
        "s.stop_recording()",
        "s.memory",
        f"bad = sorted(m for m in sys.modules if m.split('.')[0] in {forbidden!r} or m.startswith('lmm.offline'))",
        "print('imported:', ' '.join(bad) if bad else '-')",
        "import lmm.offline.evaluation",
        "print('torch after the evaluation:', 'torch' in sys.modules)",
    ])
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=ROOT)
    assert r.returncode == 0, r.stderr
    assert r.stdout.strip().splitlines()[-2:] == ["imported: -", "torch after the evaluation: False"], r.stdout

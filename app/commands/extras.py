"""Optional dependencies of the offline commands, checked before any slow work.

``train`` needs torch, ``eval`` needs matplotlib for its plots, ``export-onnx`` needs onnx; all three come
with ``scripts/setup train`` (the ``train`` extra of pyproject.toml, torch from the PyTorch CPU index). A
command calls :func:`require` first thing and returns 2 when it says no: one line on stderr naming the
package and the command that installs it, no traceback, and the database is never loaded.
"""
from __future__ import annotations

import importlib
import sys

SETUP = "scripts/setup train"

# package -> the pip command that installs it on its own (torch: the CPU build, not PyPI's CUDA one)
PIP_INSTALL = {
    "torch": "pip install torch==2.13.0 --index-url https://download.pytorch.org/whl/cpu",
    "matplotlib": "pip install 'matplotlib>=3.8'",
    "onnx": "pip install 'onnx>=1.16'",
    "dtaidistance": "pip install 'dtaidistance>=2.3'",
    "mujoco": "pip install 'mujoco>=3.1'",
}
# packages whose extra is not the train one: package -> how to install that extra
EXTRA_SETUP = {"mujoco": "pip install -e '.[physics]'"}
# optional speed-ups a command works without: package -> the pyproject extra that holds it
SPEEDUP_EXTRA = {"dtaidistance": "search"}


def require(command: str, *packages: str, purpose: str = "") -> bool:
    """True when every package imports; otherwise print one ``error:`` line for the first that does not."""
    for name in packages:
        try:
            importlib.import_module(name)
        except ImportError as e:
            why = "is not installed" if _missing(e, name) else f"failed to import ({e})"
            print(f"lmm-studio {command}: error: needs {name}{purpose}, which {why}: install it with {EXTRA_SETUP.get(name, SETUP)} "
                  f"(or: {PIP_INSTALL.get(name, f'pip install {name}')})", file=sys.stderr)
            return False
    return True


def _missing(e: ImportError, name: str) -> bool:
    # the package itself is absent (or blocked), as opposed to a broken install failing inside it
    return isinstance(e, ModuleNotFoundError) and (e.name is None or e.name == name)


def suggest(command: str, package: str, purpose: str, available: bool | None = None) -> bool:
    """For a speed-up a command works without (``find`` re-ranks by DTW in numpy when dtaidistance is
    missing): True when ``package`` is usable (``available``, else it imports); otherwise one ``note:`` line
    on stderr saying what it would bring and how to install it, and the command goes on."""
    if available is None:
        try:
            importlib.import_module(package)
            available = True
        except ImportError:
            available = False
    if not available:
        extra = SPEEDUP_EXTRA.get(package, package)
        print(f"note: lmm-studio {command} {purpose} without {package}, which is not installed: "
              f"pip install -e '.[{extra}]' (or: {PIP_INSTALL.get(package, f'pip install {package}')})",
              file=sys.stderr)
    return bool(available)

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
}


def require(command: str, *packages: str, purpose: str = "") -> bool:
    """True when every package imports; otherwise print one ``error:`` line for the first that does not."""
    for name in packages:
        try:
            importlib.import_module(name)
        except ImportError as e:
            why = "is not installed" if _missing(e, name) else f"failed to import ({e})"
            print(f"error: lmm-studio {command} needs {name}{purpose}, which {why}: install it with {SETUP} "
                  f"(or: {PIP_INSTALL.get(name, f'pip install {name}')})", file=sys.stderr)
            return False
    return True


def _missing(e: ImportError, name: str) -> bool:
    # the package itself is absent (or blocked), as opposed to a broken install failing inside it
    return isinstance(e, ModuleNotFoundError) and (e.name is None or e.name == name)

# Shared by scripts/studio, scripts/test and scripts/setup: create the venv once and install the project into it.
# Usage: . scripts/_venv.sh [extra]   (extra: "" for the studio, "train" for train/eval/export-onnx, "test")
# Environment: LMM_VENV (venv folder, default .venv), PYTHON (interpreter that makes it, default python3),
# LMM_TORCH_INDEX (where the pinned torch comes from, default the PyTorch CPU index; see README "Two commands").
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${LMM_VENV:-$ROOT/.venv}"
EXTRA="${1:-}"
PY="${PYTHON:-python3}"
TORCH_VERSION="2.13.0"
TORCH_CPU_INDEX="https://download.pytorch.org/whl/cpu"

# The pinned torch, CPU build. A bare `pip install torch` from PyPI is the CUDA build on Linux (about 4 GB of
# nvidia-* and cuda-* wheels), so the torch wheel is installed alone, before the project, from exactly one place:
#  1. a wheel pip already has on local disk (its configured find-links; --no-index: no network, no wait);
#  2. otherwise the PyTorch CPU index, and only that index: with PyPI beside it, an unreachable CPU index
#     makes pip fall back to PyPI's CUDA build without a word.
# Then torch's small dependencies (sympy, networkx, jinja2, ...) come from pip's usual indexes; the installed
# torch already satisfies the pin, so pip never swaps it for another build.
# LMM_TORCH_INDEX=URL skips step 1 and uses URL instead of the CPU index (a mirror, or a CUDA index on purpose).
install_torch() {
  local pip=("$VENV/bin/python" -m pip)
  if "$VENV/bin/python" -c "import importlib.metadata as m, sys; sys.exit(m.version('torch').split('+')[0] != '$TORCH_VERSION')" 2>/dev/null; then
    return 0
  fi
  if [ -z "${LMM_TORCH_INDEX:-}" ] && "${pip[@]}" install -q --no-index --no-deps "torch==$TORCH_VERSION" >/dev/null 2>&1; then
    echo "[setup] torch $TORCH_VERSION from a local wheel (pip's find-links)" >&2
  else
    local index="${LMM_TORCH_INDEX:-$TORCH_CPU_INDEX}"
    echo "[setup] torch $TORCH_VERSION from $index" >&2
    if ! "${pip[@]}" install -q --no-deps "torch==$TORCH_VERSION" --index-url "$index" >&2; then
      echo "[setup] error: could not install torch==$TORCH_VERSION from $index; set LMM_TORCH_INDEX to an index" \
           "that has it (a mirror of $TORCH_CPU_INDEX) or put the wheel in a pip find-links folder" >&2
      exit 1
    fi
  fi
  "${pip[@]}" install -q "torch==$TORCH_VERSION" >&2  # its dependencies
  # say which build it is: a CUDA build lists nvidia-* requirements, the CPU build none
  "$VENV/bin/python" - >&2 <<'EOF'
import importlib.metadata as m
cuda = [r.split(";")[0].strip() for r in m.requires("torch") or [] if r.startswith("nvidia")]
print(f"[setup] installed torch {m.version('torch')}: "
      + (f"a CUDA build ({len(cuda)} nvidia-* requirements)" if cuda else "CPU build (no nvidia-* requirements)"))
EOF
}

if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating $VENV" >&2
  "$PY" -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip >&2
fi
STAMP="$VENV/.lmm-installed-${EXTRA:-runtime}"
# setuptools warns on every editable install that folders named like the packages in the working directory
# may shadow them: here the working directory is this checkout, whose folders are the packages
# (only for these two pip commands, not for what the scripts run afterwards)
QUIET_EDITABLE="${PYTHONWARNINGS:+$PYTHONWARNINGS,}ignore:Editable installation:Warning"
if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ]; then
  if [ -n "$EXTRA" ]; then
    install_torch
    echo "[setup] installing lmm-studio[$EXTRA] into $VENV" >&2
    PYTHONWARNINGS="$QUIET_EDITABLE" "$VENV/bin/python" -m pip install -q -e "$ROOT[$EXTRA]" >&2
  else
    echo "[setup] installing lmm-studio into $VENV" >&2
    PYTHONWARNINGS="$QUIET_EDITABLE" "$VENV/bin/python" -m pip install -q -e "$ROOT" >&2
  fi
  touch "$STAMP"
fi

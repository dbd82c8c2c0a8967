# Shared by scripts/studio and scripts/test: create .venv once and install the project into it.
# Usage: . scripts/_venv.sh [extra]   (extra: "" for the studio, "test" for the test suite)
set -euo pipefail
ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
VENV="${LMM_VENV:-$ROOT/.venv}"
EXTRA="${1:-}"
PY="${PYTHON:-python3}"
if [ ! -x "$VENV/bin/python" ]; then
  echo "[setup] creating $VENV" >&2
  "$PY" -m venv "$VENV"
  "$VENV/bin/python" -m pip install -q --upgrade pip >&2
fi
STAMP="$VENV/.lmm-installed-${EXTRA:-runtime}"
if [ ! -f "$STAMP" ] || [ "$ROOT/pyproject.toml" -nt "$STAMP" ]; then
  if [ -n "$EXTRA" ]; then
    # The pinned CPU build first: a bare torch requirement would pull several GB of CUDA wheels.
    "$VENV/bin/python" -m pip install -q "torch==2.13.0" >&2
    echo "[setup] installing lmm-studio[$EXTRA]" >&2
    "$VENV/bin/python" -m pip install -q -e "$ROOT[$EXTRA]" >&2
  else
    echo "[setup] installing lmm-studio" >&2
    "$VENV/bin/python" -m pip install -q -e "$ROOT" >&2
  fi
  touch "$STAMP"
fi

#!/usr/bin/env bash
# Set up the kit on a fresh Debian/Ubuntu-like machine, CPU only:
#   - the system libraries for off-screen rendering (EGL + Mesa), when absent and we are root;
#   - a virtual environment in .venv with torch==2.13.0 (CPU) kept pinned by constraints.txt;
#   - the kit itself, editable, with its test extras.
# Idempotent: a second run only checks. Any failure stops with a message (set -e).
#
# On a GPU machine keep your CUDA build of torch: AIRPOSE_KEEP_TORCH=1 bash scripts/setup.sh
# skips the torch pin when a torch is already importable (a new .venv then sees the system's
# packages; or point AIRPOSE_VENV at the environment that has it) and installs the rest under
# constraints.txt without its torch line.
set -euo pipefail
cd "$(dirname "$0")/.."

PYTHON=${PYTHON:-python3}
VENV=${AIRPOSE_VENV:-.venv}

log() { printf '[setup] %s\n' "$*"; }

# 1. Off-screen rendering needs libEGL and a Mesa driver (llvmpipe). VTK's wheel brings the rest.
need_apt=()
ldconfig -p | grep -q 'libEGL.so.1' || need_apt+=(libegl1 libegl-mesa0)
ldconfig -p | grep -q 'libGL.so.1' || need_apt+=(libgl1 libglx-mesa0)
compgen -G '/usr/lib/*/dri/swrast_dri.so' >/dev/null || compgen -G '/usr/lib/*/dri/*llvmpipe*' >/dev/null \
  || need_apt+=(libgl1-mesa-dri)
ldconfig -p | grep -q 'libXrender.so.1' || need_apt+=(libxrender1)
if [ ${#need_apt[@]} -gt 0 ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    log "installing Debian packages for off-screen rendering: ${need_apt[*]}"
    DEBIAN_FRONTEND=noninteractive apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq "${need_apt[@]}" >/dev/null
  else
    echo "[setup] missing system libraries for off-screen rendering: ${need_apt[*]}" >&2
    echo "[setup] install them (e.g. sudo apt-get install ${need_apt[*]}) and run again" >&2
    exit 1
  fi
fi

# 2. Virtual environment.
KEEP_TORCH=${AIRPOSE_KEEP_TORCH:-0}
if [ ! -x "$VENV/bin/python" ]; then
  log "creating $VENV with $($PYTHON --version)"
  venv_flags=()
  [ "$KEEP_TORCH" = 1 ] && venv_flags=(--system-site-packages)  # the system's CUDA torch stays visible
  "$PYTHON" -m venv "${venv_flags[@]}" "$VENV"
fi
PIP=("$VENV/bin/python" -m pip --disable-pip-version-check)

# 3. torch first, CPU build, exactly the pinned version (an unpinned torch pulls CUDA wheels);
#    with AIRPOSE_KEEP_TORCH=1 the torch already there, whatever its version and build.
CONSTRAINTS=constraints.txt
if [ "$KEEP_TORCH" = 1 ]; then
  if ! "$VENV/bin/python" -c 'import torch' 2>/dev/null; then
    echo "[setup] AIRPOSE_KEEP_TORCH=1 but $VENV has no torch to keep: install your CUDA torch into it first" >&2
    echo "[setup] (e.g. $VENV/bin/pip install torch --index-url https://download.pytorch.org/whl/cu124), or drop AIRPOSE_KEEP_TORCH" >&2
    exit 1
  fi
  log "keeping $("$VENV/bin/python" -c 'import torch; print("torch", torch.__version__, "CUDA", torch.version.cuda)')"
  CONSTRAINTS=$(mktemp)
  trap 'rm -f "$CONSTRAINTS"' EXIT
  grep -v -E '^torch(==|>|<|~|$)' constraints.txt > "$CONSTRAINTS"
elif ! "$VENV/bin/python" -c 'import torch, sys; sys.exit(torch.__version__.split("+")[0] != "2.13.0")' 2>/dev/null; then
  log "installing torch==2.13.0 (CPU)"
  extra=()
  [ -n "${AIRPOSE_TORCH_INDEX_URL:-}" ] && extra=(--index-url "$AIRPOSE_TORCH_INDEX_URL")
  "${PIP[@]}" install -q "${extra[@]}" -c constraints.txt torch==2.13.0
fi

# 4. The kit and everything else, always under the constraints.
log "installing airpose_lib and its dependencies"
"${PIP[@]}" install -q -c "$CONSTRAINTS" -e ".[test]"

AIRPOSE_KEEP_TORCH=$KEEP_TORCH "$VENV/bin/python" - <<'PY'
import os
import torch
assert os.environ["AIRPOSE_KEEP_TORCH"] == "1" or torch.__version__.startswith("2.13.0"), torch.__version__
import airpose_lib, smplx, anny, pyvista, papermill  # noqa: F401
print(f"[setup] ok: torch {torch.__version__}, kit at {airpose_lib.__file__}")
PY

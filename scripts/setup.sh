#!/usr/bin/env bash
# Stylize3D set-up: installs everything (system libraries when root, a virtual environment in .venv,
# the package with its test extra), then either opens the app or runs the whole test suite headless.
#
#   bash scripts/setup.sh app [MESH]   install, then open the app (default: the bundled sample mesh)
#   bash scripts/setup.sh test [ARGS]  install, then run the whole test suite headless (pytest ARGS)
#
# Idempotent: a second run re-installs only when pyproject.toml changed.
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
mode="${1:-}"; shift || true
case "$mode" in app|test) ;; *) echo "usage: bash scripts/setup.sh app [MESH] | test [PYTEST ARGS]" >&2; exit 2;; esac

PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null || PY=python3
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' 2>/dev/null || {
  echo "Stylize3D needs Python 3.11 (found: $("$PY" --version 2>&1)). Set PYTHON=/path/to/python3.11." >&2; exit 2; }

# --- system libraries: Xvfb + Mesa software OpenGL + Qt's xcb platform dependencies --------------
sys_pkgs=(xvfb xauth libgl1 libgl1-mesa-dri libegl1 libglu1-mesa libxkbcommon0 libxkbcommon-x11-0
  libxcb-cursor0 libxcb-icccm4 libxcb-keysyms1 libxcb-image0 libxcb-render-util0 libxcb-shape0
  libxcb-xinerama0 libxcb-randr0 libxcb-xfixes0 libxcb-xkb1 libxcb-shm0 libxcb-sync1 libxrender1
  libxi6 libsm6 libice6 libfontconfig1 libfreetype6 libdbus-1-3 libxext6 libx11-xcb1 fonts-dejavu-core)
if command -v dpkg-query >/dev/null; then
  missing=()
  for p in "${sys_pkgs[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  if [ ${#missing[@]} -gt 0 ]; then
    if [ "$(id -u)" = 0 ]; then
      echo ">> installing system packages: ${missing[*]}"
      apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    elif command -v sudo >/dev/null; then
      sudo apt-get update -qq && sudo DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends "${missing[@]}" >/dev/null
    else
      echo "!! missing system packages (install them for the viewport): ${missing[*]}" >&2
    fi
  fi
fi

# --- virtual environment ----------------------------------------------------------------------
if [ ! -x .venv/bin/python ]; then
  echo ">> creating .venv"
  "$PY" -m venv .venv
fi
stamp=.venv/.stylize3d-installed
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo ">> installing Stylize3D and its dependencies into .venv (first time: a few minutes)"
  log=.venv/install.log
  pipi() { .venv/bin/python -m pip install --no-input "$@" >>"$log" 2>&1 || {
    echo "!! pip install $* failed; the last lines of $log:" >&2; tail -n 30 "$log" >&2; exit 1; }; }
  : > "$log"
  pipi --upgrade pip setuptools wheel
  # torch first, exactly pinned: it then satisfies every later requirement without a CUDA download.
  pipi "torch==2.13.0"
  pipi -e ".[test]"
  # compile the Numba kernels now (cached next to the sources) rather than on first use
  .venv/bin/python -m algorithms.warmup >>"$log" 2>&1 || echo "!! kernel warm-up failed (see $log); they compile on first use" >&2
  echo "$want" > "$stamp"
  echo ">> installed (log: $log)"
fi

if [ "$mode" = app ]; then
  # the mesh is the first argument unless that is an option (app --screenshot FILE opens the
  # sample too, instead of taking "--screenshot" for a mesh)
  mesh=resources/samples/blob.obj
  if [ $# -gt 0 ] && [ "${1#-}" = "$1" ]; then mesh="$1"; shift; fi
  if [ -z "${DISPLAY:-}" ] && [ -z "${WAYLAND_DISPLAY:-}" ] && command -v xvfb-run >/dev/null; then
    echo ">> no display found: running on a virtual X server (xvfb-run)"
    exec xvfb-run -a -s "-screen 0 1600x1000x24" .venv/bin/stylize3d "$mesh" "$@"
  fi
  exec .venv/bin/stylize3d "$mesh" "$@"
else
  # pytest-xvfb starts a virtual X server for the viewport tests; without Xvfb they skip, saying why.
  unset DISPLAY WAYLAND_DISPLAY
  export QT_QPA_PLATFORM=xcb PYVISTA_OFF_SCREEN=false
  exec .venv/bin/python -m pytest -q -p no:cacheprovider "$@"
fi

#!/usr/bin/env bash
# One-folder desktop build of Stylize3D with PyInstaller, then its smoke test.
#
#   bash packaging/build.sh            build venv (first time), PyInstaller, smoke test
#   bash packaging/build.sh --no-test  build only
#
# Everything goes under packaging/.build/ (git-ignored):
#   venv/              the build venv: torch==2.13.0 first (CPU wheel, as scripts/setup.sh does),
#                      then the project with its `packaging` extra (pyinstaller, hooks-contrib);
#                      re-installed only when pyproject.toml changed
#   work/              PyInstaller's work folder
#   dist/stylize3d/    THE BUNDLE: stylize3d (binary), _internal/, stylize3d.desktop, stylize3d.png
#   smoke/             smoke-test results (cubic.obj, screenshots, timings.json)
#   build.log          pip and PyInstaller output
# The smoke test compares with the project's venv (.venv) when there is one (STYLIZE3D_VENV=...
# to name another). Heavy steps run under `nice -n 19` (shared machines). Needs Python 3.11 and,
# for the smoke test, xvfb-run (scripts/setup.sh installs the system libraries).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$here"
test_too=1
[ "${1:-}" = "--no-test" ] && test_too=0

B=packaging/.build
mkdir -p "$B"
log="$B/build.log"
: > "$log"
PY="${PYTHON:-python3.11}"
command -v "$PY" >/dev/null || PY=python3
"$PY" -c 'import sys; assert sys.version_info[:2] == (3, 11), sys.version' 2>/dev/null || {
  echo "The build needs Python 3.11 (found: $("$PY" --version 2>&1)). Set PYTHON=/path/to/python3.11." >&2; exit 2; }
t_start=$(date +%s)

# --- build venv ---------------------------------------------------------------------------------
if [ ! -x "$B/venv/bin/python" ]; then
  echo ">> creating the build venv ($B/venv)"
  "$PY" -m venv "$B/venv"
fi
stamp="$B/venv/.stylize3d-build-installed"
want="$(sha256sum pyproject.toml | cut -d' ' -f1)"
pipi() { nice -n 19 "$B/venv/bin/python" -m pip install --no-input "$@" >>"$log" 2>&1 || {
  echo "!! pip install $* failed; the last lines of $log:" >&2; tail -n 30 "$log" >&2; exit 1; }; }
if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
  echo ">> installing Stylize3D with its packaging extra into the build venv (first time: minutes)"
  pipi --upgrade pip setuptools wheel
  # torch first, exactly pinned: it then satisfies every later requirement without a CUDA download.
  pipi "torch==2.13.0"
  # not editable: PyInstaller analyses the sources in the repository (pathex in the spec); the
  # installed copy only brings the dependencies and their metadata.
  pipi ".[packaging]"
  echo "$want" > "$stamp"
fi
t_venv=$(date +%s)

# --- PyInstaller --------------------------------------------------------------------------------
echo ">> PyInstaller (one folder; log: $log)"
rm -rf "$B/dist/stylize3d"
nice -n 19 "$B/venv/bin/python" -m PyInstaller --noconfirm --clean --log-level WARN \
  --distpath "$B/dist" --workpath "$B/work" packaging/stylize3d.spec >>"$log" 2>&1 || {
  echo "!! PyInstaller failed; the last lines of $log:" >&2; tail -n 40 "$log" >&2; exit 1; }
cp packaging/stylize3d.desktop packaging/stylize3d.png "$B/dist/stylize3d/"
t_build=$(date +%s)
size_mb=$(du -sm "$B/dist/stylize3d" | cut -f1)
echo ">> bundle: $B/dist/stylize3d/stylize3d (${size_mb} MB on disk; venv $((t_venv - t_start)) s," \
  "PyInstaller $((t_build - t_venv)) s)"

# --- smoke test ---------------------------------------------------------------------------------
if [ "$test_too" = 1 ]; then
  venv="${STYLIZE3D_VENV:-.venv}"
  cmp=()
  [ -x "$venv/bin/stylize3d" ] && cmp=(--venv "$venv")
  rm -rf "$B/smoke"
  nice -n 19 "$B/venv/bin/python" packaging/smoke_test.py "$B/dist/stylize3d" --out "$B/smoke" "${cmp[@]}"
  echo ">> smoke test passed ($(( $(date +%s) - t_build )) s); total $(( $(date +%s) - t_start )) s"
fi

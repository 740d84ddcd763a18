#!/usr/bin/env bash
# flexmech set-up on Debian/Ubuntu: system packages (gfortran, LAPACK, pkg-config),
# a virtual environment in .venv, and the package built and installed into it.
#   bash .ci/setup.sh            set up only
#   bash .ci/setup.sh reproduce  set up, then run `flexmech reproduce --out reproduce`
#   bash .ci/setup.sh test       set up, then run the test suite
set -euo pipefail
cd "$(dirname "$0")/.."
say() { printf 'flexmech setup: %s\n' "$*"; }
die() { printf 'flexmech setup: ERROR: %s\n' "$*" >&2; exit 1; }

# --- system packages ---------------------------------------------------------------
need=()
command -v gfortran >/dev/null 2>&1 || need+=(gfortran)
command -v pkg-config >/dev/null 2>&1 || need+=(pkg-config)
pkg-config --exists lapack 2>/dev/null || need+=(liblapack-dev libblas-dev)
python3 -c 'import venv, ensurepip' >/dev/null 2>&1 || need+=(python3-venv)
python3 -c 'import sysconfig, os, sys; sys.exit(not os.path.exists(os.path.join(sysconfig.get_paths()["include"], "Python.h")))' \
  >/dev/null 2>&1 || need+=(python3-dev)
if [ ${#need[@]} -gt 0 ]; then
  say "installing system packages: ${need[*]}"
  if [ "$(id -u)" = 0 ]; then SUDO=""; elif command -v sudo >/dev/null 2>&1; then SUDO="sudo"; else
    die "missing ${need[*]} and no root/sudo: run 'apt-get install -y ${need[*]}' as root, then re-run this script"; fi
  command -v apt-get >/dev/null 2>&1 || die "missing ${need[*]} and no apt-get: install them with your package manager, then re-run"
  $SUDO apt-get update -qq >/dev/null || die "apt-get update failed: check the network/package mirrors, then re-run"
  DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq "${need[@]}" >/dev/null \
    || die "apt-get install ${need[*]} failed: install them by hand, then re-run"
fi
python3 -c 'import sys; sys.exit(sys.version_info < (3, 10))' || die "Python >= 3.10 is needed (found $(python3 -V)): install a newer python3"

# --- virtual environment and package --------------------------------------------------
if [ ! -x .venv/bin/python ]; then
  say "creating virtual environment .venv"
  python3 -m venv .venv || die "python3 -m venv failed: apt-get install python3-venv, then re-run"
fi
PY=.venv/bin/python
# distributed: the optional Dask executor (pip install 'flexmech[cluster]'), needed by tests/test_cluster.py;
# rainflow: the optional fatigue count (pip install 'flexmech[fatigue]'), needed by tests/test_design.py;
# pythonfmu: the optional FMU export (pip install 'flexmech[fmi]') and fmpy, the FMI master, needed by tests/test_fmu.py
DEPS=("meson-python>=0.15" "meson>=1.1" ninja "numpy>=1.23" "scipy>=1.9" "matplotlib>=3.5" "pytest>=7" "distributed>=2024.1"
      "rainflow>=3.2" "pythonfmu>=0.7" "fmpy>=0.3.20")
DEPS_STAMP=.venv/.flexmech-deps          # the dependency list last installed into .venv
BUILD_STAMP=.venv/.flexmech-build        # hash of the sources the installed package was built from
LOG=build/flexmech-build.log             # the last build's log (build/ is git-ignored)
if [ "$(cat "$DEPS_STAMP" 2>/dev/null)" = "${DEPS[*]}" ] \
   && $PY -c 'import mesonpy, numpy, scipy, matplotlib, pytest, distributed, rainflow, pythonfmu, fmpy' >/dev/null 2>&1; then
  say "build tools and dependencies: already installed"
else
  $PY -m pip install -q --upgrade pip >/dev/null
  say "installing build tools and dependencies"
  $PY -m pip install -q "${DEPS[@]}" || die "pip could not install the Python dependencies: check access to the package index"
  printf '%s' "${DEPS[*]}" > "$DEPS_STAMP"
fi

# rebuild only when a file the package is built from changed (or nothing is installed yet)
sources=$(find fortran flexmech_py cases meson.build meson.options pyproject.toml -type f \
            ! -name '*.pyc' ! -path '*/__pycache__/*' -print0 | LC_ALL=C sort -z | xargs -0 sha256sum | sha256sum)
sources=${sources%% *}
if [ "$(cat "$BUILD_STAMP" 2>/dev/null)" = "$sources" ] && .venv/bin/flexmech --version >/dev/null 2>&1; then
  say "flexmech is up to date with the sources (nothing to rebuild; last build log: $LOG)"
else
  say "building and installing flexmech (Fortran kernels, f2py; log: $LOG)"
  mkdir -p build
  rm -f "$BUILD_STAMP"
  $PY -m pip install -q --no-build-isolation . >"$LOG" 2>&1 \
    || { tail -30 "$LOG" >&2; die "the build failed (full log: $LOG)"; }
  printf '%s' "$sources" > "$BUILD_STAMP"
fi
version=$(.venv/bin/flexmech --version) || die "the installed package does not import (see the lines above; build log: $LOG)"
say "ready: $version"

# the test command also opens `flexmech view` pages in a real browser (tests/test_view_browser.py):
# Debian's chromium and chromium-driver, and selenium; without them those tests are skipped, saying why
browser_for_tests() {
  local pkgs=()
  command -v chromium >/dev/null 2>&1 || pkgs+=(chromium)
  command -v chromedriver >/dev/null 2>&1 || pkgs+=(chromium-driver)
  if [ ${#pkgs[@]} -gt 0 ]; then
    local sudo=""
    [ "$(id -u)" = 0 ] || sudo=$(command -v sudo || true)
    if command -v apt-get >/dev/null 2>&1 && { [ "$(id -u)" = 0 ] || [ -n "$sudo" ]; }; then
      say "installing ${pkgs[*]} (the browser tests of flexmech view)"
      $sudo apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -qq "${pkgs[@]}" >/dev/null \
        || say "could not install ${pkgs[*]}: the browser tests will be skipped"
    else
      say "no ${pkgs[*]} and no way to install them: the browser tests will be skipped"
    fi
  fi
  $PY -c 'import selenium' >/dev/null 2>&1 || $PY -m pip install -q "selenium>=4" \
    || say "could not install selenium: the browser tests will be skipped"
}

case "${1:-}" in
  reproduce) shift; exec .venv/bin/flexmech reproduce --out reproduce "$@" ;;
  test) shift; browser_for_tests; exec .venv/bin/pytest -q "$@" ;;
  "") ;;
  *) die "unknown action '$1' (use: reproduce, test)" ;;
esac

#!/usr/bin/env bash
# The main job: bootstrap .venv (idempotent, fast when set up), then run a profile of the paper
# and regenerate results/. All options after the bootstrap ones go to `python -m plls_bench.reproduce`
# (run it with --help for the list).
#
#   ./reproduce.sh --profile smoke        # the whole pipeline at tiny budgets
#   ./reproduce.sh --setup-only           # only create/refresh .venv and check GL libraries
#   ./reproduce.sh --setup-only --dev     # the same, with the dev extra (pytest, mkdocs, ruff) for tests and docs
set -euo pipefail
cd "$(dirname "$0")"

VENV="${PLLS_VENV:-.venv}"
PYTHON="${PYTHON:-python3}"
GL_PACKAGES=(libegl1 libgl1-mesa-dri libosmesa6)   # headless OpenGL for dm_control (EGL, OSMesa)

say() { printf '[reproduce] %s\n' "$*" >&2; }

check_python() {
  if ! "$PYTHON" -c 'import sys; sys.exit(sys.version_info < (3, 11))' 2>/dev/null; then
    say "error: $PYTHON is missing or older than Python 3.11; set PYTHON=/path/to/python3.11"
    exit 2
  fi
}

setup_gl() {
  command -v dpkg-query >/dev/null 2>&1 || { say "not a Debian system: make sure EGL or OSMesa is installed for dm_control rendering"; return 0; }
  local missing=() p
  for p in "${GL_PACKAGES[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" || missing+=("$p")
  done
  [ ${#missing[@]} -eq 0 ] && return 0
  if [ "$(id -u)" -eq 0 ] && command -v apt-get >/dev/null 2>&1; then
    say "installing Debian GL libraries: ${missing[*]}"
    # another setup (a second worktree) may hold dpkg's lock: wait for it rather than fail
    apt-get -o DPkg::Lock::Timeout=600 update -qq >/dev/null
    DEBIAN_FRONTEND=noninteractive apt-get -o DPkg::Lock::Timeout=600 install -y -qq --no-install-recommends \
      "${missing[@]}" >/dev/null
  else
    say "warning: missing GL libraries for headless rendering: ${missing[*]}"
    say "         install them with: sudo apt-get install ${missing[*]}"
  fi
}

pip_install() {
  # This machine's pip config lists local index folders that may be absent; pip then prints one
  # harmless warning per package. Drop those lines; pip's own exit status still decides.
  "$VENV/bin/python" -m pip install -q "$@" 2>&1 | { grep -v "is ignored: it is neither a file nor a directory" || true; }
}

setup_venv() {
  local stamp="$VENV/.plls-stamp" want
  want="$(cat pyproject.toml | sha256sum | cut -c1-16)"
  if [ ! -f "$stamp" ] || [ "$(cat "$stamp")" != "$want" ]; then
    check_python
    [ -x "$VENV/bin/python" ] || { say "creating $VENV"; "$PYTHON" -m venv "$VENV"; }
    say "installing pinned dependencies into $VENV (first run only)"
    # torch first and alone: the pinned CPU wheel, so no other requirement drags in a CUDA build.
    pip_install torch==2.13.0
    pip_install -e .
    echo "$want" > "$stamp"
  fi
  # The dev extra (tests, docs site) on top, with its own stamp, so a plain setup never drops it.
  if [ "$dev" -eq 1 ] && [ "$(cat "$stamp.dev" 2>/dev/null)" != "$want" ]; then
    say "installing the dev extra (pytest, mkdocs, ruff) into $VENV"
    pip_install -e ".[dev]"
    echo "$want" > "$stamp.dev"
  fi
}

setup_only=0
dev=0
args=()
for a in "$@"; do
  case "$a" in
    --setup-only) setup_only=1 ;;
    --dev) dev=1 ;;
    *) args+=("$a") ;;
  esac
done

setup_gl
setup_venv
[ "$setup_only" -eq 1 ] && exit 0
exec "$VENV/bin/python" -m plls_bench.reproduce "${args[@]+"${args[@]}"}"

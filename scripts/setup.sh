#!/usr/bin/env bash
# Idempotent set-up from nothing: project-local venv from the lock file, then a colcon build
# of every package under src/ into ros2_ws/install. Re-running it only redoes what changed.
#
#   scripts/setup.sh            # create/update .venv and build the workspace
#   FORCE=1 scripts/setup.sh    # rebuild everything
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
venv="$root/.venv"
python_bin="${PYTHON:-python3.11}"
command -v "$python_bin" >/dev/null 2>&1 || python_bin=python3

log() { printf '[setup] %s\n' "$*"; }

hash_of() { cat "$@" 2>/dev/null | sha256sum | cut -d' ' -f1; }

# 1. The virtual environment, reinstalled only when the lock files change.
req_hash="$(hash_of requirements/lock.txt requirements/mediapipe.txt requirements/render.txt requirements/tf2.txt requirements/ray.txt)"
if [ "${FORCE:-0}" = 1 ] || [ ! -x "$venv/bin/python" ] || [ "$(cat "$venv/.lock-hash" 2>/dev/null)" != "$req_hash" ]; then
  log "creating $venv with $("$python_bin" --version 2>&1)"
  [ -x "$venv/bin/python" ] || "$python_bin" -m venv "$venv"
  "$venv/bin/python" -m pip install --quiet --upgrade pip 2>&1 | { grep -v "is ignored: it is neither" || true; }
  log "installing requirements/lock.txt (torch==2.13.0 CPU, ROS 2 Jazzy wheels, Pinocchio, ...)"
  "$venv/bin/python" -m pip install --quiet -r requirements/lock.txt 2>&1 | { grep -v "is ignored: it is neither" || true; }
  "$venv/bin/python" -m pip install --quiet --no-deps -r requirements/mediapipe.txt 2>&1 | { grep -v "is ignored: it is neither" || true; }
  "$venv/bin/python" -m pip install --quiet --no-deps -r requirements/render.txt 2>&1 | { grep -v "is ignored: it is neither" || true; }
  "$venv/bin/python" -m pip install --quiet --no-deps -r requirements/tf2.txt 2>&1 | { grep -v "is ignored: it is neither" || true; }
  "$venv/bin/python" -m pip install --quiet --no-deps -r requirements/ray.txt 2>&1 | { grep -v "is ignored: it is neither" || true; }
  echo "$req_hash" > "$venv/.lock-hash"
else
  log "venv up to date"
fi

# 2. The OSMesa library for CPU rendering (mocap data render, its test). Only data generation
#    needs it; without it the render command says what is missing and its tests skip.
if ! ldconfig -p 2>/dev/null | grep -q 'libOSMesa\.so'; then
  as_root=""
  if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
    as_root="sudo -n"
  fi
  if { [ "$(id -u)" = 0 ] || [ -n "$as_root" ]; } && command -v apt-get >/dev/null 2>&1; then
    log "installing libosmesa6 (CPU OpenGL for rendering people)"
    { DEBIAN_FRONTEND=noninteractive $as_root apt-get install -y --no-install-recommends libosmesa6 >/dev/null 2>&1 \
      || { $as_root apt-get update >/dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive $as_root apt-get install -y --no-install-recommends libosmesa6 >/dev/null 2>&1; }; } \
      || log "could not install libosmesa6: mocap data render will not work (the rest does)"
  else
    log "note: libOSMesa not found; mocap data render needs it (Debian: sudo apt-get install libosmesa6)"
  fi
fi

# 3. tf2_msgs (for /tf) is built from its message definition in the workspace: it needs a C/C++
#    compiler and CMake. A full ROS install's own tf2_msgs is used instead when importable.
skip=()
system_tf2() {   # a sourced ROS install (not this workspace) provides tf2_msgs
  [ -n "${ROS_DISTRO:-}" ] || return 1
  local pp
  pp="$(printf '%s' "${PYTHONPATH:-}" | tr ':' '\n' | grep -v "^$root/" | paste -sd: -)"
  PYTHONPATH="$pp" python3 -c 'import tf2_msgs' 2>/dev/null
}
if system_tf2; then
  log "tf2_msgs found in the ROS install: using it"
  skip=(--packages-skip tf2_msgs)
else
  missing=()
  command -v cmake >/dev/null 2>&1 || missing+=(cmake)
  command -v cc >/dev/null 2>&1 || missing+=(gcc)
  command -v c++ >/dev/null 2>&1 || missing+=(g++)
  if [ "${#missing[@]}" -gt 0 ]; then
    as_root=""
    if [ "$(id -u)" != 0 ] && command -v sudo >/dev/null 2>&1 && sudo -n true 2>/dev/null; then
      as_root="sudo -n"
    fi
    if { [ "$(id -u)" = 0 ] || [ -n "$as_root" ]; } && command -v apt-get >/dev/null 2>&1; then
      log "installing ${missing[*]} (to build tf2_msgs for /tf)"
      { DEBIAN_FRONTEND=noninteractive $as_root apt-get install -y --no-install-recommends "${missing[@]}" >/dev/null 2>&1 \
        || { $as_root apt-get update >/dev/null 2>&1 && DEBIAN_FRONTEND=noninteractive $as_root apt-get install -y --no-install-recommends "${missing[@]}" >/dev/null 2>&1; }; } \
        || true
    fi
  fi
  if ! command -v cmake >/dev/null 2>&1 || ! command -v cc >/dev/null 2>&1 || ! command -v c++ >/dev/null 2>&1; then
    log "note: no C/C++ compiler or CMake: tf2_msgs is not built and the nodes publish no /tf (Debian: sudo apt-get install cmake g++)"
    skip=(--packages-skip tf2_msgs)
  fi
fi

# 4. The colcon workspace; rebuilt when any package manifest changes or install/ is missing.
pkg_hash="$(hash_of $(find src -maxdepth 2 \( -name package.xml -o -name setup.py -o -name setup.cfg -o -name CMakeLists.txt \) | sort) $(find src/tf2_msgs/msg -name '*.msg' | sort)) ${skip[*]:-}"
stamp="ros2_ws/install/.pkg-hash"
if [ "${FORCE:-0}" = 1 ] || [ ! -f ros2_ws/install/setup.bash ] || [ "$(cat "$stamp" 2>/dev/null)" != "$pkg_hash" ]; then
  log "colcon build (symlink install) of src/*"
  (
    cd ros2_ws
    # shellcheck disable=SC1091
    source "$venv/bin/activate"
    # ament_cmake, the rosidl generators and the message packages are CMake packages in the venv
    export CMAKE_PREFIX_PATH="$venv${CMAKE_PREFIX_PATH:+:$CMAKE_PREFIX_PATH}"
    # ... found through the ament index the pip-installed ROS keeps in the venv (typesupports)
    export AMENT_PREFIX_PATH="$venv${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}"
    rm -rf build install log
    colcon --log-base log build --symlink-install --event-handlers console_direct- console_stderr- \
      "${skip[@]}" --cmake-args -Wno-dev -Wno-deprecated >/dev/null \
      || { log "colcon build failed: see ros2_ws/log/latest_build"; exit 1; }
  )
  echo "$pkg_hash" > "$stamp"
else
  log "workspace up to date"
fi
log "done: source env.sh to use ros2, mocap and the nodes"

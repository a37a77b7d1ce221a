#!/usr/bin/env bash
# The pipeline live, each node in its own process with `ros2 run` (what
# `ros2 launch mocap_core pipeline.launch.py` does on a machine with a full ROS 2 install).
#
#   scripts/live.sh camera [DEVICE]        # a camera (default 0)
#   scripts/live.sh video FILE             # a video file at its frame rate
#   scripts/live.sh bag BAG                # ros2 bag play of a bag with images or keypoints
#   scripts/live.sh none                   # lifter, physics, gmr only (feed them yourself)
#   scripts/live.sh composed video FILE    # the four nodes in one process (mocap run);
#   scripts/live.sh composed camera [DEV]  #   also for a camera
#
# Environment: RECORD=folder also records every pipeline topic with `ros2 bag record`;
# LIFTER_MODE=causal|windowed, LIFTER_MODEL=motionet|vtm, GAINS=fixed|learned,
# STATIC_CAMERA=true|false.
# Stop with Ctrl-C (file sources and bags stop by themselves). Logs: $LOGS (default out/live).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
# shellcheck disable=SC1091
source env.sh
kind="${1:-camera}"
arg="${2:-}"
logs="${LOGS:-out/live}"
mkdir -p "$logs"
pids=()
stop() { for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done; wait || true; }
trap stop EXIT INT TERM

if [[ "$kind" == composed ]]; then
  # one process: mocap run (messages handed over in process; DDS for outside subscribers)
  src="${2:-camera}"
  case "$src" in
    video)  run_src=(--video "${3:?usage: scripts/live.sh composed video FILE}") ;;
    camera) run_src=(--camera "${3:-0}") ;;
    *) echo "usage: scripts/live.sh composed video FILE | composed camera [DEVICE]" >&2; exit 2 ;;
  esac
  if [[ -n "${RECORD:-}" ]]; then
    ros2 bag record -o "$RECORD" -a > "$logs/record.log" 2>&1 &
    pids+=("$!")
    echo "[live] recording every topic to $RECORD"
  fi
  exec_args=("${run_src[@]}" --param "lifter.mode=${LIFTER_MODE:-windowed}"
             --param "lifter.model=${LIFTER_MODEL:-motionet}"
             --param "physics.gains_mode=${GAINS:-fixed}"
             --param "gmr.static_camera=${STATIC_CAMERA:-false}")
  mocap run "${exec_args[@]}"
  exit $?
fi

if [[ -n "${RECORD:-}" ]]; then
  topics=(/mocap/keypoints2d /mocap/camera_info /mocap/camera/motion /mocap/skeleton/urdf
          /diagnostics
          /mocap/lifter/contacts /mocap/physics/grf/left /mocap/physics/grf/right
          /mocap/physics/com /mocap/physics/floor /mocap/world/floor /mocap/world/odom
          /mocap/world/path)
  for s in lifter physics world; do
    for l in motion joints3d joint_states markers; do topics+=("/mocap/$s/$l"); done
  done
  ros2 bag record -o "$RECORD" "${topics[@]}" > "$logs/record.log" 2>&1 &
  pids+=("$!")
  echo "[live] recording to $RECORD"
fi
ros2 run mocap_lifter lifter --ros-args -p mode:="${LIFTER_MODE:-windowed}" \
  -p model:="${LIFTER_MODEL:-motionet}" \
  > "$logs/lifter.log" 2>&1 &
pids+=("$!")
ros2 run mocap_physics physics --ros-args -p gains_mode:="${GAINS:-fixed}" \
  > "$logs/physics.log" 2>&1 &
pids+=("$!")
ros2 run mocap_global gmr --ros-args -p static_camera:="${STATIC_CAMERA:-false}" \
  > "$logs/gmr.log" 2>&1 &
pids+=("$!")
for n in lifter physics gmr; do
  for _ in $(seq 1 600); do grep -q "ready\|physics on" "$logs/$n.log" 2>/dev/null && break; sleep 0.1; done
  echo "[live] $n: $(grep -m1 "ready\|physics on" "$logs/$n.log" || echo 'not ready, see its log')"
done
case "$kind" in
  camera) ros2 run mocap_keypoints keypoints --ros-args -p source:=camera -p device:="${arg:-0}" ;;
  video)  ros2 run mocap_keypoints keypoints --ros-args -p path:="$arg" -p realtime:=true \
            -p wait_for_subscribers:=1 ;;
  bag)    if ros2 bag info "$arg" | grep -q 'sensor_msgs/msg/Image'; then
            ros2 run mocap_keypoints keypoints --ros-args -p source:=topic > "$logs/keypoints.log" 2>&1 &
            pids+=("$!")
          fi
          ros2 bag play "$arg" --delay 3 ;;
  none)   echo "[live] nodes running; publish /mocap/keypoints2d (Ctrl-C to stop)"; wait ;;
  *) echo "usage: scripts/live.sh camera [DEVICE] | video FILE | bag BAG | none" >&2; exit 2 ;;
esac
sleep 3   # frames waiting for look-ahead leave the lifter and GMR

#!/usr/bin/env bash
# The demo on real data shipped in the repository: a real 4 s video clip
# (data/video_example/taiji_640x360.mp4, a person doing tai chi) goes through the pipeline's
# nodes, each started with `ros2 run` in its own process, and everything is recorded with
# `ros2 bag record`:
#
#   keypoints (MediaPipe BlazePose on the video) -> lifter (MotioNet, shipped weights)
#
# Output: out/demo/ (or $1): the MCAP bag, its info and validation, keypoints.png (2D
# skeletons over time) and motion.png (the lifted 3D skeleton, front and side views).
# Later stages (physics, world frame) join this script as they land.
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
# shellcheck disable=SC1091
source env.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 200) + 1 ))}"
out="${1:-out/demo}"
video="${DEMO_VIDEO:-data/video_example/taiji_640x360.mp4}"
rm -rf "$out"
mkdir -p "$out"
bag="$out/demo_bag"
pids=()
cleanup() { for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done; }
trap cleanup EXIT

wait_for() {  # wait_for FILE TEXT SECONDS
  for _ in $(seq 1 $(( $3 * 10 ))); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.1; done
  echo "[demo] timed out waiting for '$2' in $1" >&2; cat "$1" >&2; return 1
}

echo "[demo] ros2 bag record -> $bag"
ros2 bag record -o "$bag" /mocap/keypoints2d /mocap/camera_info /mocap/lifter/motion \
  /mocap/lifter/joints3d /mocap/lifter/joint_states /mocap/lifter/contacts \
  /mocap/lifter/markers /mocap/skeleton/urdf /diagnostics > "$out/record.log" 2>&1 &
rec=$!
pids+=("$rec")

echo "[demo] ros2 run mocap_lifter lifter (windowed MotioNet)"
ros2 run mocap_lifter lifter > "$out/lifter.log" 2>&1 &
lifter=$!
pids+=("$lifter")
wait_for "$out/lifter.log" 'lifter ready' 120

echo "[demo] ros2 run mocap_keypoints keypoints on $video"
ros2 run mocap_keypoints keypoints --ros-args -p path:="$video" -p realtime:=true \
  -p wait_for_subscribers:=2 -p wait_timeout_s:=30.0 2>&1 | tee "$out/keypoints.log"

sleep 3   # the lifter emits the frames that waited for look-ahead, the recorder writes them
kill -INT "$lifter" 2>/dev/null || true
wait "$lifter" 2>/dev/null || true
kill -INT "$rec"
wait "$rec" || true
trap - EXIT

echo "[demo] ros2 bag info $bag"
ros2 bag info "$bag" | tee "$out/bag_info.txt"
echo "[demo] mocap bag check $bag"
mocap bag check "$bag" | tee "$out/bag_check.txt"
mocap plot keypoints "$bag" -o "$out/keypoints.png"
mocap plot motion "$bag" --topic /mocap/lifter/motion -o "$out/motion.png"
mocap export bvh "$bag" --topic /mocap/lifter/motion -o "$out/lifter.bvh"
echo "[demo] done: results in $out/"

#!/usr/bin/env bash
# The demo on real data shipped in the repository: real OpenPose detections of an in-the-wild
# clip (data/openpose_example/seq1) go through the keypoint node, started with `ros2 run`, and
# are recorded with `ros2 bag record`; the bag is then summarised and validated. Later stages
# of the pipeline join this script as their nodes land.
#
# Output: out/demo/ (the bag, its info, a plot of the keypoints).
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
# shellcheck disable=SC1091
source env.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 200) + 1 ))}"
out="${1:-out/demo}"
rm -rf "$out"
mkdir -p "$out"
bag="$out/keypoints_bag"

echo "[demo] recording /mocap/keypoints2d and /mocap/camera_info to $bag"
ros2 bag record -o "$bag" /mocap/keypoints2d /mocap/camera_info /diagnostics > "$out/record.log" 2>&1 &
rec=$!
trap 'kill -INT $rec 2>/dev/null || true' EXIT

echo "[demo] ros2 run mocap_keypoints keypoints (81 real OpenPose frames at 30 fps)"
ros2 run mocap_keypoints keypoints --ros-args \
  -p source:=openpose_json -p path:=data/openpose_example/seq1 -p fps:=30.0 \
  -p wait_for_subscribers:=1 -p wait_timeout_s:=20.0 2>&1 | tee "$out/keypoints.log"

sleep 1
kill -INT $rec
wait $rec || true
trap - EXIT

echo "[demo] ros2 bag info $bag"
ros2 bag info "$bag" | tee "$out/bag_info.txt"
echo "[demo] mocap bag check $bag"
mocap bag check "$bag" | tee "$out/bag_check.txt"
mocap plot keypoints "$bag" -o "$out/keypoints.png"
echo "[demo] done: results in $out/"

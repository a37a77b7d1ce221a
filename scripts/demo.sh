#!/usr/bin/env bash
# The demo on real data shipped in the repository: a real 4 s video clip
# (data/video_example/taiji_640x360.mp4, a person doing tai chi) goes through the four nodes of
# the pipeline, each started with `ros2 run` in its own process, at the video's frame rate, and
# everything is recorded with `ros2 bag record`:
#
#   keypoints (MediaPipe BlazePose) -> lifter (MotioNet) -> physics (PD + GRF + no penetration,
#   Pinocchio) -> gmr (world-frame motion, bidirectional GRU)
#
# Then the same video goes through `mocap process` (the same node classes in one process, no
# frame dropped, as fast as possible) for comparison.
#
# Output: out/demo/ (or $1): the recorded bag (demo_bag/), report.md (frames, rates, per-node
# processing time, plausibility), pipeline.mp4 (video frames with 2D keypoints beside the world
# skeleton from the side and the front, with foot contacts and ground reaction forces),
# pipeline_frames.png (a few of those frames), root_trajectory.png, grf.png, torques.png,
# lifter.bvh and world.bvh; process_bag/ and process_report/ for the offline run; logs.
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
mkdir -p "$out/logs"
bag="$out/demo_bag"
pids=()
cleanup() { for p in "${pids[@]}"; do kill -INT "$p" 2>/dev/null || true; done; }
trap cleanup EXIT

wait_for() {  # wait_for FILE TEXT SECONDS
  for _ in $(seq 1 $(( $3 * 10 ))); do grep -q "$2" "$1" 2>/dev/null && return 0; sleep 0.1; done
  echo "[demo] timed out waiting for '$2' in $1" >&2; cat "$1" >&2; return 1
}

topics=(/mocap/keypoints2d /mocap/camera_info /mocap/camera/motion /mocap/skeleton/urdf
        /diagnostics
        /mocap/lifter/contacts /mocap/physics/grf/left /mocap/physics/grf/right
        /mocap/physics/com /mocap/physics/floor /mocap/world/floor /mocap/world/odom
        /mocap/world/path /mocap/lifter/unsmoothed_motion)
for stage in lifter physics world; do
  for leaf in motion joints3d joint_states markers; do topics+=("/mocap/$stage/$leaf"); done
done
echo "[demo] ros2 bag record -> $bag"
ros2 bag record -o "$bag" "${topics[@]}" > "$out/logs/record.log" 2>&1 &
rec=$!
pids+=("$rec")

start_node() {  # start_node PACKAGE EXECUTABLE READY_TEXT
  echo "[demo] ros2 run $1 $2"
  ros2 run "$1" "$2" > "$out/logs/$2.log" 2>&1 &
  pids+=("$!")
  eval "pid_$2=$!"
}
start_node mocap_lifter lifter 'lifter ready'
start_node mocap_physics physics 'physics on'
start_node mocap_global gmr 'gmr ready'
wait_for "$out/logs/lifter.log" 'lifter ready' 120
wait_for "$out/logs/physics.log" 'physics on' 120
wait_for "$out/logs/gmr.log" 'gmr ready' 120
wait_for "$out/logs/record.log" 'Recording' 60
# Every stage subscribed to the one before (DDS discovery between processes can take a few
# seconds on a loaded machine): otherwise the first frames would leave before anyone listens.
python3 - <<'PY'
import time
import rclpy
rclpy.init()
node = rclpy.create_node('demo_graph_check')
need = {'/mocap/lifter/motion': 2, '/mocap/lifter/contacts': 2,
        '/mocap/physics/motion': 2}
deadline = time.monotonic() + 30
while time.monotonic() < deadline:
    missing = {t: n for t, n in need.items() if node.count_subscribers(t) < n}
    if not missing:
        break
    time.sleep(0.2)
print('[demo] subscribers matched' if not missing else f'[demo] still waiting for {missing}')
node.destroy_node()
rclpy.shutdown()
PY
sleep 1

echo "[demo] ros2 run mocap_keypoints keypoints on $video (at its frame rate)"
t0=$(date +%s.%N)
ros2 run mocap_keypoints keypoints --ros-args -p path:="$video" -p realtime:=true \
  -p wait_for_subscribers:=2 -p wait_timeout_s:=30.0 2>&1 | tee "$out/logs/keypoints.log"
t1=$(date +%s.%N)

sleep 4   # frames held for look-ahead leave the lifter and GMR; the recorder writes them
for p in "$pid_lifter" "$pid_physics" "$pid_gmr"; do kill -INT "$p" 2>/dev/null || true; done
for p in "$pid_lifter" "$pid_physics" "$pid_gmr"; do wait "$p" 2>/dev/null || true; done
kill -INT "$rec"
wait "$rec" || true
trap - EXIT

echo "[demo] ros2 bag info $bag"
ros2 bag info "$bag" | tee "$out/bag_info.txt"
mocap bag check "$bag" > "$out/bag_check.txt"
wall=$(python3 -c "print(f'{$t1 - $t0:.2f}')")
mocap report "$bag" -o "$out" --video "$video" --wall-seconds "$wall" \
  --title "Demo: $(basename "$video"), four nodes live (ros2 run), recorded with ros2 bag record" \
  --note "keypoints at the video's frame rate (realtime), BlazePose; lifter: windowed MotioNet; physics: fixed gains; GMR: look-ahead per its defaults"
mocap export bvh "$bag" --topic /mocap/lifter/motion -o "$out/lifter.bvh"
mocap export bvh "$bag" --topic /mocap/world/motion --frame world -o "$out/world.bvh"

echo "[demo] mocap process $video (the same nodes in one process, offline)"
mocap process "$video" -o "$out/process_bag" --no-progress --summary "$out/process_summary.json" \
  > "$out/logs/process.log" 2>&1
tail -n 1 "$out/logs/process.log" || true
grep '^processed' "$out/logs/process.log" || true
mocap report "$out/process_bag" -o "$out/process_report" \
  --title "Offline: mocap process $(basename "$video")" > /dev/null
echo "[demo] done: results in $out/ (start with $out/report.md and $out/pipeline.mp4)"

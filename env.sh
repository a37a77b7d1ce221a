# Source this file (bash or zsh) to use the project's venv, workspace, `ros2` and `mocap`.
#   source env.sh
_mocap_root="$(cd "$(dirname "${BASH_SOURCE[0]:-${(%):-%x}}")" && pwd)"
if [ ! -f "$_mocap_root/ros2_ws/install/setup.bash" ]; then
  echo "env.sh: run scripts/setup.sh (or make setup) first" >&2
  return 1 2>/dev/null || exit 1
fi
# The activate and colcon scripts read unset variables: relax `set -u` while sourcing them.
case $- in *u*) _mocap_nounset=1; set +u ;; *) _mocap_nounset=0 ;; esac
# shellcheck disable=SC1091
source "$_mocap_root/.venv/bin/activate"
# shellcheck disable=SC1091
source "$_mocap_root/ros2_ws/install/setup.bash"
[ "$_mocap_nounset" = 1 ] && set -u
unset _mocap_nounset
# pip-installed ROS indexes the standard message packages under the venv itself.
case ":${AMENT_PREFIX_PATH:-}:" in
  *":$VIRTUAL_ENV:"*) ;;
  *) export AMENT_PREFIX_PATH="$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}" ;;
esac
export MOCAP_ROOT="$_mocap_root"
unset _mocap_root

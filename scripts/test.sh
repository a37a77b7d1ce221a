#!/usr/bin/env bash
# Runs every test (unit tests of each package and the integration tests in test/).
# Extra arguments go to pytest, e.g. scripts/test.sh -k bag -x
set -euo pipefail
root="$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)"
cd "$root"
# shellcheck disable=SC1091
source env.sh
# Keep DDS traffic on this machine and away from other runs.
export ROS_AUTOMATIC_DISCOVERY_RANGE="${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}"
export ROS_DOMAIN_ID="${ROS_DOMAIN_ID:-$(( (RANDOM % 200) + 1 ))}"
# Wrongly typed message fields raise instead of serialising garbage.
export ROS_PYTHON_CHECK_FIELDS=1
export PYTHONDONTWRITEBYTECODE=1
echo "[test] ROS_DOMAIN_ID=$ROS_DOMAIN_ID"
# pytest exits 5 when it collects no test: that is a failure here, like any non-zero code.
exec python -m pytest "$@"

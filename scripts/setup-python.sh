#!/usr/bin/env bash
# Creates .venv with the Python peers the interop tests compare against (pinned, so a new
# release cannot change what "byte-equal to a real ROS 2 tool" means under us).
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
if [ ! -x .venv/bin/python ]; then
  "$PY" -m venv .venv
fi
.venv/bin/python -m pip install --quiet --disable-pip-version-check -r tests/py/requirements.txt
.venv/bin/python -c "import rosbags, mcap, mcap_ros2; print('python peers ready:', rosbags.__name__, mcap.__name__, mcap_ros2.__name__)"

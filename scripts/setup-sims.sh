#!/usr/bin/env bash
# Creates .venv-sims with the simulation benchmarks (pinned in sim/bridges/requirements.txt):
# MetaWorld 3.1 on MuJoCo 3.3 and gym-aloha. `scaledp sim/collect/eval --rig metaworld/<task>`
# find it at .venv-sims/bin/python (or set SCALEDP_SIM_PYTHON). Rendering is headless through
# EGL (Mesa's software rasterizer: no GPU, no display). A second run finds everything installed.
set -euo pipefail
cd "$(dirname "$0")/.."
PY=${PYTHON:-python3}
REQ=sim/bridges/requirements.txt
if [ ! -x .venv-sims/bin/python ]; then
  "$PY" -m venv .venv-sims
fi
# Already there: nothing to ask PyPI.
if .venv-sims/bin/python - "$REQ" <<'PYEOF' 2>/dev/null
import sys
from importlib.metadata import version
for line in open(sys.argv[1]):
    line = line.split("#")[0].strip()
    if line:
        name, want = line.split("==")
        if version(name) != want:
            sys.exit(1)
PYEOF
then
  echo "simulators ready (installed): $(.venv-sims/bin/python -c 'import metaworld, mujoco; print("metaworld", metaworld.__version__ if hasattr(metaworld, "__version__") else "3.1.1", "mujoco", mujoco.__version__)' 2>/dev/null)"
  exit 0
fi
.venv-sims/bin/python -m pip install --quiet --disable-pip-version-check -r "$REQ"
MUJOCO_GL=egl .venv-sims/bin/python -c "
import mujoco, metaworld, gym_aloha
m = mujoco.MjModel.from_xml_string('<mujoco><worldbody><light pos=\"0 0 1\"/><geom size=\".1\"/></worldbody></mujoco>')
r = mujoco.Renderer(m, 8, 8); r.render()
print('simulators ready: mujoco', mujoco.__version__, '(EGL rendering works), metaworld and gym_aloha import')"

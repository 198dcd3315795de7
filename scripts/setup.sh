#!/usr/bin/env bash
# One-command setup: .venv with pinned ROS 2 Jazzy wheels and dependencies, the wheel fixes, colcon build.
# Safe to run again: steps whose inputs did not change are skipped.
set -euo pipefail
cd "$(dirname "$0")/.."
ROOT=$PWD
VENV=$ROOT/.venv
PYTHON=${PYTHON:-python3.11}
step() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

command -v "$PYTHON" >/dev/null || PYTHON=python3
if [ ! -x "$VENV/bin/python" ]; then
  step "creating $VENV with $($PYTHON --version)"
  "$PYTHON" -m venv "$VENV"
else
  step "using existing $VENV"
fi

req_hash=$(cat requirements.txt requirements-runtime.txt constraints.txt | sha1sum | cut -d' ' -f1)
if [ "$(cat "$VENV/.cap-requirements" 2>/dev/null)" != "$req_hash" ]; then
  step "installing pinned packages (requirements*.txt, constraints.txt)"
  # This machine's pip configuration names extra index folders that may be absent; pip warns once per package.
  "$VENV/bin/python" -m pip install --disable-pip-version-check -q -r requirements.txt -c constraints.txt 2>&1 \
    | { grep -v "is ignored: it is neither a file nor a directory" || true; }
  echo "$req_hash" > "$VENV/.cap-requirements"
else
  step "pinned packages already installed"
fi

step "fixing the ROS wheels' CMake exports"
"$VENV/bin/python" scripts/fix_ros_wheels.py

# The standard interfaces (control_msgs, nav2_msgs, tf2_msgs) are built here only where the ROS prefix lacks them:
# the PyPI wheels do; a regular ROS 2 install does not (scripts/standard_interfaces.py).
standard=$(AMENT_PREFIX_PATH=$VENV "$VENV/bin/python" scripts/standard_interfaces.py | tr '\n' ' ')
# Build inputs only: with --symlink-install, edits to Python modules need no rebuild, while manifests, setup files,
# interface definitions, resources and config do, and so does a module added or removed (setup.py files offer the
# modules of their plug-in folders as entry points): the list of module paths counts, not their contents.
src_hash=$( (find ros_ws/src -type f \( -name package.xml -o -name setup.py -o -name setup.cfg -o -name CMakeLists.txt \
    -o -name '*.msg' -o -name '*.srv' -o -name '*.action' -o -path '*/resource/*' -o -path '*/config/*' \
    -o -path '*/launch/*' \) -print0 | sort -z | xargs -0 sha1sum; find ros_ws/src -name '*.py' | sort;
    find ros_ws/standard_interfaces -type f -print0 | sort -z | xargs -0 sha1sum; echo "$standard $req_hash") \
    | sha1sum | cut -d' ' -f1)
if [ "$(cat ros_ws/install/.cap-source 2>/dev/null)" != "$src_hash" ]; then
  step "building ros_ws with colcon"
  # A renamed or removed config or launch file leaves its --symlink-install link dangling, and colcon then fails to
  # copy it: links to nothing go first.
  [ -d ros_ws/build ] && find ros_ws/build ros_ws/install -xtype l -delete 2>/dev/null || true
  (
    export VIRTUAL_ENV=$VENV PATH=$VENV/bin:$PATH
    # The venv is the ament prefix: without this CMake finds no rosidl package (the ROS wheels' CMake files look for packages under it).
    export AMENT_PREFIX_PATH=$VENV CMAKE_PREFIX_PATH=$VENV
    cd ros_ws
    # shellcheck disable=SC2086  # one base path per word
    colcon --log-base log build --symlink-install --base-paths src $standard \
      --event-handlers console_cohesion- summary+ \
      --cmake-args -DPython3_EXECUTABLE="$VENV/bin/python" -DBUILD_TESTING=OFF
  )
  echo "$src_hash" > ros_ws/install/.cap-source
else
  step "ros_ws is up to date"
fi
step "done; use it with: source scripts/env.sh"

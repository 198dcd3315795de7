# Source this file (bash) to use the built workspace: the venv, the ROS wheels and ros_ws/install.
# Keeps DDS discovery on this host; choose your own ROS_DOMAIN_ID to keep graphs apart.
_cap_root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
export VIRTUAL_ENV=$_cap_root/.venv
export PATH=$VIRTUAL_ENV/bin:$PATH
export AMENT_PREFIX_PATH=$VIRTUAL_ENV${AMENT_PREFIX_PATH:+:$AMENT_PREFIX_PATH}
export ROS_AUTOMATIC_DISCOVERY_RANGE=${ROS_AUTOMATIC_DISCOVERY_RANGE:-LOCALHOST}
export MUJOCO_GL=${MUJOCO_GL:-egl}
# The `cap` command line (installed where `ros2 run cap_bringup cap` finds it on a regular install).
export PATH=$_cap_root/ros_ws/install/cap_bringup/lib/cap_bringup:$PATH
set +u
# shellcheck disable=SC1091
. "$_cap_root/ros_ws/install/local_setup.bash"
unset _cap_root

#!/usr/bin/env bash
# The table-top demo: brings up the simulated graph and runs the demo commands (see cap_bringup/demos/tabletop.py).
# Offline by default (demo cassette of reference programs). With CAP_LLM_BASE_URL set, the commands go to that
# OpenAI-compatible endpoint instead. Extra arguments go to the demo, e.g. --out DIR, --perception rgbd.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck disable=SC1091
. scripts/env.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
# A domain of its own unless the caller chose one (keeps the demo apart from other graphs on this host).
export ROS_DOMAIN_ID=${ROS_DOMAIN_ID:-$(( $$ % 100 + 1 ))}
exec python -m cap_bringup.demos.tabletop "$@"

#!/usr/bin/env bash
# Runs every package's unit tests and the integration tests in tests/. Extra arguments go to pytest.
# Each test gets its own ROS_DOMAIN_ID and localhost-only discovery from the fixture in conftest.py.
set -euo pipefail
cd "$(dirname "$0")/.."
# shellcheck disable=SC1091
. scripts/env.sh
export ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST
exec python -m pytest "$@"

#!/usr/bin/env bash
# The table-top demo. The end-to-end graph (lmp_node, cap CLI) is not in place yet.
set -euo pipefail
cd "$(dirname "$0")/.."
echo "[demo] coming: the table-top demo arrives with the lmp_node and the cap command line."

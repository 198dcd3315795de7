#!/usr/bin/env bash
# `make browser`: the headless browser the console's tests drive: Debian's Chromium, from the system's package
# manager (never a browser build of its own: Playwright's own download is never used). Run by `make test`.
set -euo pipefail
CHROMIUM=${CAP_CHROMIUM:-/usr/bin/chromium}
step() { printf '\033[1m[browser]\033[0m %s\n' "$*"; }
if [ -x "$CHROMIUM" ]; then
  step "$("$CHROMIUM" --version 2>/dev/null || echo chromium) at $CHROMIUM"
  exit 0
fi
if [ "$(id -u)" != 0 ]; then
  echo "no Chromium at $CHROMIUM: install Debian's package as root (apt-get install chromium), then run this again" >&2
  exit 1
fi
step "installing Debian's chromium (apt-get)"
export DEBIAN_FRONTEND=noninteractive
apt-get update -q >/dev/null
apt-get install -y -q --no-install-recommends chromium >/dev/null
step "$("$CHROMIUM" --version) at $CHROMIUM"

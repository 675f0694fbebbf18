#!/usr/bin/env bash
# Headless Chromium (Debian's package `chromium`) for the report's browser test; part of the
# set-up that `make test` runs (`make browser`). Idempotent: nothing to do when a chromium is
# on PATH. Writes what the set-up promises to STATE (the test reads it):
#   chromium PATH    a browser is there: the browser test runs, and fails if it is gone
#   none REASON      it cannot be installed here (no apt-get, not root): the test is skipped
#                    with REASON, which this script also prints, on one line
#   failed REASON    root and apt-get were there but the install failed: the test fails
set -uo pipefail
state=${1:?usage: install_browser.sh STATE_FILE}
mkdir -p "$(dirname "$state")"

find_chromium() { command -v chromium || command -v chromium-browser || true; }

found=$(find_chromium)
if [ -n "$found" ]; then
    echo "chromium $found" > "$state"
    exit 0
fi
why=""
if ! command -v apt-get > /dev/null; then
    why="chromium is not installed and there is no apt-get to install it"
elif [ "$(id -u)" != 0 ]; then
    why="chromium is not installed and installing it needs root (apt-get install chromium)"
fi
if [ -n "$why" ]; then
    echo "make browser: NO BROWSER: $why; the report's browser test will be SKIPPED" >&2
    echo "none $why" > "$state"
    exit 0
fi

echo "make browser: installing chromium with apt-get (once; for the report's browser test)"
log=$(mktemp)
apt() { DEBIAN_FRONTEND=noninteractive apt-get -q -o DPkg::Lock::Timeout=300 "$@" >> "$log" 2>&1; }
# a fresh machine has empty or stale package lists: update once, then install
apt install -y --no-install-recommends chromium || { apt update && apt install -y --no-install-recommends chromium; }
found=$(find_chromium)
if [ -n "$found" ]; then
    echo "chromium $found" > "$state"
    echo "make browser: installed $("$found" --version 2>/dev/null || echo "$found")"
else
    last=$(grep -v '^\s*$' "$log" | tail -n 1)
    echo "make browser: could not install chromium with apt-get: ${last:-no output}; the browser test will FAIL" >&2
    echo "failed apt-get could not install chromium: ${last:-no output}" > "$state"
fi
rm -f "$log"
exit 0

#!/usr/bin/env bash
# What the browser test needs besides the kit (run after scripts/setup.sh): Debian's Chromium
# (installed when absent and we are root) and Playwright (the kit's `browser` extra), which
# drives that Chromium and never downloads a browser of its own.
set -euo pipefail
cd "$(dirname "$0")/.."
VENV=${AIRPOSE_VENV:-.venv}
CHROMIUM=${AIRPOSE_CHROMIUM:-/usr/bin/chromium}

if [ ! -x "$CHROMIUM" ]; then
  if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo "[setup-browser] installing Debian's chromium"
    DEBIAN_FRONTEND=noninteractive apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq chromium >/dev/null
  else
    echo "[setup-browser] no Chromium at $CHROMIUM: install it (sudo apt-get install chromium) or set AIRPOSE_CHROMIUM" >&2
    exit 1
  fi
fi
"$VENV/bin/python" -m pip --disable-pip-version-check install -q -c constraints.txt -e ".[test,browser]"
echo "[setup-browser] ok: $("$CHROMIUM" --version 2>/dev/null | head -1)"

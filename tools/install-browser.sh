#!/usr/bin/env bash
# Install Debian's chromium if it is missing, for the viewer's screenshot test
# (tests/test_viewer.py), which skips without a browser.
#   bash tools/install-browser.sh
# Needs root and apt-get; otherwise it prints a note and exits 0 (the test skips).
set -u

if command -v chromium >/dev/null 2>&1 || [ -x /usr/bin/chromium ]; then
  exit 0
fi
if [ "$(id -u)" != 0 ] || ! command -v apt-get >/dev/null 2>&1; then
  echo "note: chromium is missing and cannot be installed here (needs root and apt-get);" \
    "the viewer's screenshot test will be skipped"
  exit 0
fi
if ! (apt-get update -qq >/dev/null && DEBIAN_FRONTEND=noninteractive \
  apt-get install -y -qq chromium >/dev/null); then
  echo "note: 'apt-get install chromium' failed; the viewer's screenshot test will be skipped"
  exit 0
fi
echo "installed chromium: $(command -v chromium || echo /usr/bin/chromium)"

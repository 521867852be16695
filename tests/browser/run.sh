#!/usr/bin/env bash
# The browser viewer's tests (viewer.test.mjs) in Chromium against a real brickcastd.
# Installs playwright-core from package-lock.json (npm ci) when node_modules is missing or older
# than the lock file; downloads no browser. Exit status: the tests'.
#
# Environment: BRICKCASTD (default ../../build/tools/brickcastd), BRICKCAST (the CLI, default
# ../../build/tools/brickcast), BC_CHROMIUM (default /usr/bin/chromium), BC_VIEWER_SCREENSHOT
# (write a screenshot of the viewer there), BC_WEB_DIR (serve web/ from this folder instead of
# the copy compiled into brickcastd, e.g. $PWD/web before a rebuild).
set -euo pipefail
here="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
cd "$here"
if [[ ! -d node_modules/playwright-core || node_modules -ot package-lock.json ]]; then
  PLAYWRIGHT_SKIP_BROWSER_DOWNLOAD=1 npm ci --no-audit --no-fund
  touch node_modules
fi
exec node --test --test-reporter=spec "$@" "$here/viewer.test.mjs"

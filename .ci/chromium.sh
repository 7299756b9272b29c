#!/usr/bin/env bash
# Installs what the console's browser test needs from the distribution's
# packages when it is missing (as root, with apt-get): Chromium, which the
# test runs headless against `goby console` (cli/tests/console.rs). Without
# it that test is ignored at run time and says why.
set -euo pipefail
have_chromium() { command -v chromium >/dev/null || command -v chromium-browser >/dev/null; }
if have_chromium; then
    exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo ".ci/chromium.sh: installing chromium"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends chromium fonts-dejavu-core >/dev/null
    exit 0
fi
echo ".ci/chromium.sh: chromium not found and cannot be installed here (needs root and apt-get); the console's browser test will be skipped" >&2

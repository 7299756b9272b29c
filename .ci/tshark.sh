#!/usr/bin/env bash
# Installs what the Wireshark dissector's test needs from the distribution's
# packages when it is missing (as root, with apt-get): tshark, which captures
# two gobyd on loopback and reads the capture with the dissector `goby dccl
# wireshark` writes (cli/tests/wireshark.rs). Without it that test is
# ignored and says why.
set -euo pipefail
if command -v tshark >/dev/null; then
    exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo ".ci/tshark.sh: installing tshark"
    apt-get update -qq
    # Captures run as root here: no dumpcap group asked for.
    echo "wireshark-common wireshark-common/install-setuid boolean false" | debconf-set-selections
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends tshark >/dev/null
    exit 0
fi
echo ".ci/tshark.sh: tshark not found and cannot be installed here (needs root and apt-get); the Wireshark dissector's test will be skipped" >&2

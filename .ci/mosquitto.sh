#!/usr/bin/env bash
# Installs the Mosquitto MQTT broker from the distribution's packages when it
# is missing (as root, with apt-get), for gobyd's MQTT bridge tests
# (`cargo test -p gobyd --test mqtt`), which start their own broker on a
# free loopback port and say they are skipped when none is found.
set -euo pipefail
if command -v mosquitto >/dev/null || [ -x /usr/sbin/mosquitto ]; then
    exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo ".ci/mosquitto.sh: installing mosquitto"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mosquitto >/dev/null
    # The package's own service is not wanted: the tests run their broker.
    exit 0
fi
echo ".ci/mosquitto.sh: mosquitto not found and cannot be installed here (needs root and apt-get); the MQTT tests will be skipped" >&2

#!/usr/bin/env bash
# Installs what the MQTT tests need from the distribution's packages when it
# is missing (as root, with apt-get): the Mosquitto broker, for gobyd's MQTT
# bridge tests and `goby mqtt watch`'s (they start their own broker on a free
# loopback port), and openssl, which makes the TLS test's certificates.
# Without them those tests fail, naming what is missing.
set -euo pipefail
have_mosquitto() { command -v mosquitto >/dev/null || [ -x /usr/sbin/mosquitto ]; }
if have_mosquitto && command -v openssl >/dev/null; then
    exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo ".ci/mosquitto.sh: installing mosquitto and openssl"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq mosquitto openssl >/dev/null
    # The package's own service is not wanted: the tests run their broker.
    exit 0
fi
echo ".ci/mosquitto.sh: mosquitto or openssl not found and cannot be installed here (needs root and apt-get); the MQTT tests will fail" >&2

#!/usr/bin/env bash
# Makes sure cargo-nextest, which runs the test suite, is installed: from
# crates.io when it is missing (a few minutes, once).
set -euo pipefail
if cargo nextest --version >/dev/null 2>&1; then
    exit 0
fi
echo ".ci/nextest.sh: installing cargo-nextest from crates.io"
cargo install --locked cargo-nextest

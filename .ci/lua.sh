#!/usr/bin/env bash
# Installs the Lua 5.3 interpreter from the distribution's packages when it
# is missing (as root, with apt-get): dccl's test of its condition evaluator
# against Lua (`dccl/src/conditions/lua_differential.rs`) runs it. Without
# it that test says it is skipped. The product itself never runs Lua.
set -euo pipefail
if command -v lua5.3 >/dev/null; then
    exit 0
fi
if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
    echo ".ci/lua.sh: installing lua5.3"
    apt-get update -qq
    DEBIAN_FRONTEND=noninteractive apt-get install -y -qq lua5.3 >/dev/null
    exit 0
fi
echo ".ci/lua.sh: lua5.3 not found and cannot be installed here (needs root and apt-get); the evaluator's comparison with Lua will be skipped" >&2

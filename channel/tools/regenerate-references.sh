#!/usr/bin/env bash
# Rewrites the BELLHOP references the channel crate's tests compare with
# (tests/data/bellhop/CASE.{inc.tl,coh.tl,first-arrivals} for the four cases,
# tests/data/bellhop/options/NAME.tl for the option cases) by running
# bellhop.exe on the same files: the ignored test `regenerate_references`.
#
#   bash channel/tools/install-bellhop.sh     # once, outside the repository
#   bash channel/tools/regenerate-references.sh
#
# A new option case is NAME.env under tests/data/bellhop/options/ and its
# name in OPTION_CASES (tests/bellhop.rs).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
cd "$root"
exec cargo test -p goby-channel --test bellhop -- --ignored regenerate_references

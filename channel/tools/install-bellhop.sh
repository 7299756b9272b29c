#!/usr/bin/env bash
# Installs BELLHOP (bellhop.exe of the Acoustics Toolbox, as built for
# PyPI's aubellhop wheel, libgfortran bundled) under /opt/bellhop, outside
# the repository, for the live comparisons of the channel crate's tests
# and benchmarks (they look for BELLHOP_EXE, else /opt/bellhop/bellhop.exe).
# Needs pip and PyPI; run as root (or set PREFIX).
set -euo pipefail
prefix="${PREFIX:-/opt/bellhop}"
if [ -x "$prefix/bellhop.exe" ]; then
  echo "bellhop.exe already in $prefix"
  exit 0
fi
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
python3 -m pip download --quiet --no-deps --python-version 3.12 --only-binary=:all: -d "$work" aubellhop
python3 -m zipfile -e "$work"/aubellhop-*.whl "$work/wheel"
mkdir -p "$prefix/pkg"
cp -r "$work/wheel/aubellhop" "$work/wheel/aubellhop.libs" "$prefix/pkg/"
chmod +x "$prefix"/pkg/aubellhop/bin/*.exe
# The executable finds its libraries relative to its real path.
ln -sf "$prefix/pkg/aubellhop/bin/bellhop.exe" "$prefix/bellhop.exe"
echo "bellhop.exe installed in $prefix"

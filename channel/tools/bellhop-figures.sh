#!/usr/bin/env bash
# The figures of docs/channel.md: for each BELLHOP case, bellhop.exe and
# `goby channel compare` on the same .env (coherent and incoherent), the
# side-by-side PNGs and the agreement figures, and a ray plot.
#
#   cargo build --release -p goby-cli
#   BELLHOP_EXE=/opt/bellhop/bellhop.exe bash channel/tools/bellhop-figures.sh
#
# bellhop.exe comes from PyPI's aubellhop wheel (docs/channel.md); nothing
# of it lands in the repository, only the PNGs under docs/.
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
exe="${BELLHOP_EXE:-/opt/bellhop/bellhop.exe}"
goby="${GOBY:-$root/target/release/goby}"
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT
cp "$root"/channel/tests/data/bellhop/*.env "$root"/channel/tests/data/bellhop/*.bty "$work"/
cp "$root"/channel/benches/data/munk-fine.env "$work"/
cd "$work"
for case in pekeris munk summer wedge munk-fine; do
  for run in C I; do
    name="$case-$run"
    sed -e "s/^'C'\t/'$run'\t/" "$case.env" > "$name.env"
    [ -f "$case.bty" ] && cp "$case.bty" "$name.bty"
    "$exe" "$name" > /dev/null
    echo "== $case, run type $run"
    # Plots of the coherent fields, and of the summer case's incoherent one.
    if { [ "$run" = C ] && [ "$case" != munk ]; } || [ "$case-$run" = summer-I ]; then
      "$goby" channel compare "$name.env" "$name.shd" -o "$root/docs/channel-$name.png" | sed '$d'
    else
      "$goby" channel compare "$name.env" "$name.shd"
    fi
  done
done
sed -e "s/^'C'\t/'R'\t/" -e "s/^1201\t/31\t/" -e "s/^-45.0 45.0 \//-12.0 12.0 \//" summer.env > summer-rays.env
"$goby" channel tl summer-rays.env -o "$root/docs/channel-summer-rays.png" > /dev/null

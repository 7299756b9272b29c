#!/usr/bin/env bash
# The packages as a vehicle gets them (docs/vehicle.md): builds goby-rs for
# amd64 and arm64 (packaging/deb/build.sh) and the arm64 Python wheel, then
#
# - amd64: installs the package with dpkg -i (as root), checks its paths
#   (none of Goby3's), its user, its unit (systemd-analyze verify), runs
#   `gobyd-rs --check` on the shipped /etc/goby-rs/gobyd.pb.txt and a
#   `goby-rs dccl` encode/decode round trip from the installed paths, then
#   purges it;
# - arm64: unpacks the package and runs the same from its paths under
#   qemu-user;
# - the arm64 wheel: its tag, and an aarch64 extension module inside.
#
# Each check prints PASS, FAIL (then the script fails) or SKIP with the
# reason (a tool missing: .ci/packaging.sh installs them). Run from
# anywhere; PATH must hold cargo-zigbuild (the line .ci/packaging.sh prints).
# The programs and the wheel are built in the `packaging` and `release`
# profiles, or both in GOBY_PACKAGING_PROFILE when it is set (CI sets the
# unoptimised `packaging-check`, Cargo.toml).
set -uo pipefail
cd "$(dirname "$0")/.."
root=$(pwd)
target_dir=${CARGO_TARGET_DIR:-target}
profile=${GOBY_PACKAGING_PROFILE:-packaging}
if [ -n "${GOBY_PACKAGING_PROFILE:-}" ]; then wheel_profile=(--profile "$GOBY_PACKAGING_PROFILE"); else wheel_profile=(--release); fi
passed=0 failed=0 skipped=0
pass() { echo "packaging: PASS $1"; passed=$((passed + 1)); }
fail() { echo "packaging: FAIL $1"; failed=$((failed + 1)); }
skip() { echo "packaging: SKIP $1"; skipped=$((skipped + 1)); }
# check NAME CMD...: PASS when CMD succeeds, else FAIL with its output.
check() {
    local name=$1 out
    shift
    if out=$("$@" 2>&1); then pass "$name"; else fail "$name: $out"; fi
}
work=$(mktemp -d -t goby-rs-packaging.XXXXXX)
trap 'rm -rf "$work"' EXIT

# The round trip of the guide's navigation reports: encoded, decoded and
# encoded again to the same bytes (the time codec keeps the time of day),
# the decoded values those of the input. $1: goby, $2: the examples.
round_trip() {
    local goby=("${@:1:$#-1}") examples=${!#}
    local p=$examples/navigation.proto m=goby.example.NavigationReport
    "${goby[@]}" dccl encode -f "$p" -m $m < "$examples/navigation_report.txt" > "$work/a.hex" 2>/dev/null || return 1
    "${goby[@]}" dccl decode -f "$p" < "$work/a.hex" > "$work/decoded.txt" || return 1
    "${goby[@]}" dccl encode -f "$p" -m $m < "$work/decoded.txt" > "$work/b.hex" 2>/dev/null || return 1
    [ "$(wc -l < "$work/a.hex")" = 2 ] && cmp "$work/a.hex" "$work/b.hex" || return 1
    grep -q "x: 1520.4 y: -283.9 z: -41.2 heading: 271.4 speed: 1.5 veh_class: AUV battery_ok: true" "$work/decoded.txt"
}

# --check on the shipped configuration says it is valid. $1...: gobyd, $N: root.
checks_config() {
    local gobyd=("${@:1:$#-1}") prefix=${!#}
    "${gobyd[@]}" --check -c "$prefix/etc/goby-rs/gobyd.pb.txt" | grep -q "^configuration is valid"
}

# The ELF machine of a file: 62 x86-64, 183 aarch64.
elf_machine() { od -An -tu2 -j18 -N2 "$1" | tr -d ' '; }

arches=()
if ! cargo zigbuild --help >/dev/null 2>&1 || ! cargo deb --version >/dev/null 2>&1; then
    skip "packages: cargo-zigbuild or cargo-deb not found (.ci/packaging.sh installs them)"
else
    arches=(amd64)
    if rustup target list --installed 2>/dev/null | grep -qx aarch64-unknown-linux-gnu; then
        arches+=(arm64)
    else
        skip "arm64 package: the Rust target aarch64-unknown-linux-gnu is not installed"
    fi
    start=$(date +%s)
    if packaging/deb/build.sh "${arches[@]}" > "$work/debs" 2> "$work/build.log"; then
        pass "packages built for ${arches[*]} in $(( $(date +%s) - start )) s (profile $profile)"
    else
        tail -30 "$work/build.log"
        fail "packages built for ${arches[*]}"
        arches=()
    fi
fi
deb() { grep "_$1.deb\$" "$work/debs" | tail -1; }

# amd64: installed on this machine as a vehicle installs it.
if [[ " ${arches[*]} " != *" amd64 "* ]]; then
    skip "amd64 package installed: not built"
elif [ "$(id -u)" != 0 ] || ! command -v dpkg >/dev/null; then
    skip "amd64 package installed: needs root and dpkg"
elif [ "$(dpkg --print-architecture)" != amd64 ]; then
    skip "amd64 package installed: this machine is $(dpkg --print-architecture)"
else
    dpkg --purge goby-rs >/dev/null 2>&1
    check "dpkg -i $(basename "$(deb amd64)")" dpkg -i "$(deb amd64)"
    listed=$(dpkg -L goby-rs 2>/dev/null)
    missing=()
    for path in /usr/bin/gobyd-rs /usr/bin/goby-rs /usr/lib/goby-rs/bin/gobyd /usr/lib/goby-rs/bin/goby \
        /etc/goby-rs/gobyd.pb.txt /usr/lib/systemd/system/gobyd-rs@.service /usr/lib/sysusers.d/goby-rs.conf \
        /usr/share/man/man1/gobyd-rs.1.gz /usr/share/man/man1/goby-rs-dccl-encode.1.gz \
        /usr/share/bash-completion/completions/goby-rs /usr/share/zsh/vendor-completions/_gobyd-rs \
        /usr/share/fish/vendor_completions.d/goby-rs.fish /usr/share/goby-rs/examples/navigation.proto; do
        grep -qx "$path" <<< "$listed" || missing+=("$path")
    done
    # Goby3's packages own these: never ours.
    for path in /usr/bin/gobyd /usr/bin/goby; do
        grep -qx "$path" <<< "$listed" && missing+=("not $path")
    done
    if [ ${#missing[@]} = 0 ]; then pass "package paths (none of Goby3's)"; else fail "package paths: ${missing[*]}"; fi
    check "user goby-rs made at installation" getent passwd goby-rs
    check "gobyd-rs --check on the shipped /etc/goby-rs/gobyd.pb.txt" checks_config /usr/bin/gobyd-rs ""
    check "goby-rs dccl encode/decode round trip from the installed paths" \
        round_trip /usr/bin/goby-rs /usr/share/goby-rs/examples
    check "completions for the installed name" grep -q "goby-rs" /usr/share/bash-completion/completions/goby-rs
    if command -v systemd-analyze >/dev/null; then
        check "systemd-analyze verify gobyd-rs@.service" \
            systemd-analyze verify /usr/lib/systemd/system/gobyd-rs@.service
    else
        skip "systemd-analyze verify: systemd-analyze not found"
    fi
    check "dpkg --purge goby-rs" dpkg --purge goby-rs
    if [ -e /usr/bin/gobyd-rs ] || [ -e /etc/goby-rs/gobyd.pb.txt ]; then
        fail "purged: files left"
    else
        pass "purged: no file left"
    fi
fi

# arm64: the package's programs, from its paths, under qemu-user.
qemu=$(command -v qemu-aarch64-static || command -v qemu-aarch64 || true)
if [[ " ${arches[*]} " != *" arm64 "* ]]; then
    skip "arm64 programs run: the arm64 package was not built"
elif [ -z "$qemu" ] || [ ! -d /usr/aarch64-linux-gnu/lib ]; then
    skip "arm64 programs run: qemu-user-static (or qemu-user) and libc6-arm64-cross not found"
else
    arm=$work/arm64
    dpkg-deb -x "$(deb arm64)" "$arm"
    run=("$qemu" -L /usr/aarch64-linux-gnu)
    machine=$(elf_machine "$arm/usr/lib/goby-rs/bin/gobyd")
    if [ "$machine" = 183 ]; then pass "arm64 gobyd is an aarch64 program"; else fail "arm64 gobyd: ELF machine $machine"; fi
    check "arm64 gobyd --check on its shipped configuration, under qemu" \
        checks_config "${run[@]}" "$arm/usr/lib/goby-rs/bin/gobyd" "$arm"
    check "arm64 goby dccl round trip, under qemu" \
        round_trip "${run[@]}" "$arm/usr/lib/goby-rs/bin/goby" "$arm/usr/share/goby-rs/examples"
fi

# The arm64 wheel of the Python package (glibc 2.17, manylinux2014).
if ! command -v maturin >/dev/null; then
    skip "arm64 wheel: maturin not found (.ci/packaging.sh installs it)"
elif ! rustup target list --installed 2>/dev/null | grep -qx aarch64-unknown-linux-gnu; then
    skip "arm64 wheel: the Rust target aarch64-unknown-linux-gnu is not installed"
else
    start=$(date +%s)
    if maturin build "${wheel_profile[@]}" --zig --compatibility manylinux2014 --target aarch64-unknown-linux-gnu \
        -m python/Cargo.toml -o "$work/wheels" > "$work/wheel.log" 2>&1; then
        wheel=$(ls "$work"/wheels/dccl-*.whl)
        case $(basename "$wheel") in
            # Both tags, in the order maturin writes them.
            *-cp39-abi3-*manylinux_2_17_aarch64*.whl)
                pass "arm64 wheel built in $(( $(date +%s) - start )) s (${wheel_profile[*]}): $(basename "$wheel")" ;;
            *) fail "arm64 wheel tag: $(basename "$wheel")" ;;
        esac
        mkdir -p "$work/wheel" && (cd "$work/wheel" && python3 -m zipfile -e "$wheel" .)
        module=$(ls "$work"/wheel/dccl/_dccl*.so 2>/dev/null | head -1)
        if [ -n "$module" ] && [ "$(elf_machine "$module")" = 183 ]; then
            pass "arm64 wheel holds an aarch64 extension module"
        else
            fail "arm64 wheel's extension module: ${module:-none}"
        fi
        mkdir -p "$target_dir/wheels" && cp "$wheel" "$target_dir/wheels/"
    else
        tail -30 "$work/wheel.log"
        fail "arm64 wheel built"
    fi
fi

echo "packaging: $passed passed, $failed failed, $skipped skipped"
[ "$failed" = 0 ]

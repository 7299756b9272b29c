#!/usr/bin/env bash
# Builds the Debian package goby-rs for each architecture named (amd64,
# arm64; both when none is), into target/debian/goby-rs_VERSION-1_ARCH.deb.
#
# The two programs are built with cargo-zigbuild for glibc 2.28 (Debian 10,
# Ubuntu 20.04 and later, JetPack 5 on a Jetson: the vehicle computers in
# use), in the `packaging` profile (release, stripped, no LTO; another
# with GOBY_PACKAGING_PROFILE, as CI's `packaging-check`); cargo-deb
# lays out the package from gobyd/Cargo.toml's [package.metadata.deb]. The
# manual pages, the completion scripts and /etc/goby-rs/gobyd.pb.txt come
# from the programs themselves (packaging/deb/generated/), run on this
# machine, or under qemu-user for another architecture when none of this
# machine's is built.
#
# Needs: cargo-zigbuild with zig (the ziglang wheel), cargo-deb, the Rust
# targets (rustup target add aarch64-unknown-linux-gnu); .ci/packaging.sh
# installs them. Prints the path of each package built, one a line, last.
set -euo pipefail
cd "$(dirname "$0")/../.."

GLIBC=2.28
arches=("$@")
[ ${#arches[@]} -gt 0 ] || arches=(amd64 arm64)

triple() {
    case $1 in
        amd64) echo x86_64-unknown-linux-gnu ;;
        arm64) echo aarch64-unknown-linux-gnu ;;
        *) echo "packaging/deb/build.sh: unknown architecture $1 (amd64 or arm64)" >&2; exit 2 ;;
    esac
}
for arch in "${arches[@]}"; do triple "$arch" >/dev/null; done
if ! cargo zigbuild --help >/dev/null 2>&1; then
    echo "packaging/deb/build.sh: cargo-zigbuild not found (pip install cargo-zigbuild ziglang, or .ci/packaging.sh)" >&2
    exit 1
fi
if ! cargo deb --version >/dev/null 2>&1; then
    echo "packaging/deb/build.sh: cargo-deb not found (cargo install --locked cargo-deb, or .ci/packaging.sh)" >&2
    exit 1
fi
target_dir=${CARGO_TARGET_DIR:-target}
profile=${GOBY_PACKAGING_PROFILE:-packaging}

for arch in "${arches[@]}"; do
    echo "packaging/deb/build.sh: building gobyd and goby for $arch (glibc $GLIBC, profile $profile)" >&2
    cargo zigbuild --locked --profile "$profile" --target "$(triple "$arch").$GLIBC" \
        -p gobyd -p goby-cli --bin gobyd --bin goby
done

# A way to run the programs built: this machine's architecture, else under
# qemu-user with the target's C library (Debian's libc6-ARCH-cross).
host_arch=$(dpkg --print-architecture 2>/dev/null || uname -m)
run_dir=
runner=()
for arch in "${arches[@]}"; do
    dir="$target_dir/$(triple "$arch")/$profile"
    if [ "$arch" = "$host_arch" ]; then
        run_dir=$dir; runner=(); break
    fi
    cpu=$(triple "$arch"); cpu=${cpu%%-*}
    qemu=$(command -v "qemu-$cpu-static" || command -v "qemu-$cpu" || true)
    if [ -n "$qemu" ] && [ -d "/usr/$cpu-linux-gnu" ]; then
        run_dir=$dir; runner=("$qemu" -L "/usr/$cpu-linux-gnu")
    fi
done
if [ -z "$run_dir" ]; then
    echo "packaging/deb/build.sh: cannot run the programs built for ${arches[*]} here (their manual pages come from them): build $host_arch too, or install qemu-user-static and the target's libc6-*-cross" >&2
    exit 1
fi

# Called through links named as the package installs them, the programs
# write their pages and completions for those names.
gen=packaging/deb/generated
rm -rf "$gen"
mkdir -p "$gen/man1" "$gen/bash" "$gen/zsh" "$gen/fish"
links=$(mktemp -d)
trap 'rm -rf "$links"' EXIT
ln -s "$(realpath "$run_dir/gobyd")" "$links/gobyd-rs"
ln -s "$(realpath "$run_dir/goby")" "$links/goby-rs"
"${runner[@]}" "$links/gobyd-rs" --man "$gen/man1" >/dev/null
"${runner[@]}" "$links/goby-rs" man "$gen/man1" >/dev/null
gzip -9n "$gen"/man1/*.1
for name in gobyd-rs goby-rs; do
    if [ "$name" = gobyd-rs ]; then sub=(--completions); else sub=(completions); fi
    "${runner[@]}" "$links/$name" "${sub[@]}" bash > "$gen/bash/$name"
    "${runner[@]}" "$links/$name" "${sub[@]}" zsh > "$gen/zsh/_$name"
    "${runner[@]}" "$links/$name" "${sub[@]}" fish > "$gen/fish/$name.fish"
done
{
    cat packaging/deb/gobyd.pb.txt.head
    "${runner[@]}" "$links/gobyd-rs" --example-config
} > "$gen/gobyd.pb.txt"

for arch in "${arches[@]}"; do
    # The profile already stripped the programs (cargo-deb's strip is the
    # host's, which cannot strip another architecture).
    cargo deb -p gobyd --no-build --no-strip --profile "$profile" --target "$(triple "$arch")" \
        --output "$target_dir/debian/" 2>&1 | tail -1 >&2
    ls "$target_dir/debian/"goby-rs_*_"$arch".deb
done

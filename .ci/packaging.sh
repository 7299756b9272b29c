#!/usr/bin/env bash
# Installs what packaging/test.sh needs when it is missing, each from its
# registry: zig (the ziglang wheel), cargo-zigbuild and maturin into a
# virtual environment under target/ (PyPI); cargo-deb (crates.io); the
# arm64 Rust standard library (rustup); qemu-user-static and the arm64 C
# library, for running arm64 programs here (Debian's packages, as root).
# What cannot be installed is said here, and the tests needing it are
# skipped, saying why. Prints the directory to put first on the PATH.
# With --cargo-deb, installs cargo-deb only, and with --debian the Debian
# packages only (.ci/run does each apart, beside other work).
set -euo pipefail
cd "$(dirname "$0")/.."
venv=${CARGO_TARGET_DIR:-target}/packaging-tools
say() { echo ".ci/packaging.sh: $*" >&2; }

# cargo-deb, built unoptimised (a quarter of the build's time) but for its
# xz compressor, whose speed is all of cargo-deb's work on a package.
install_cargo_deb() {
    cargo deb --version >/dev/null 2>&1 && return 0
    say "installing cargo-deb from crates.io"
    cargo install --locked cargo-deb@3.8.0 \
        --config 'profile.release.opt-level=0' \
        --config 'profile.release.package.lzma-sys.opt-level=3' >&2 \
        || say "cannot install cargo-deb: the packages will not be built"
}
# qemu-user-static and the arm64 C library, to run arm64 programs here.
install_debian() {
    have_qemu() { command -v qemu-aarch64-static >/dev/null || command -v qemu-aarch64 >/dev/null; }
    have_qemu && [ -d /usr/aarch64-linux-gnu/lib ] && return 0
    if [ "$(id -u)" = 0 ] && command -v apt-get >/dev/null; then
        say "installing qemu-user-static and libc6-arm64-cross"
        apt-get update -qq >&2
        DEBIAN_FRONTEND=noninteractive apt-get install -y -qq --no-install-recommends \
            qemu-user-static libc6-arm64-cross >/dev/null \
            || say "cannot install qemu-user-static: arm64 programs will not be run"
    else
        say "qemu-user-static not found and cannot be installed here (needs root and apt-get): arm64 programs will not be run"
    fi
}
case "${1:-}" in
    --cargo-deb) install_cargo_deb; exit 0 ;;
    --debian) install_debian; exit 0 ;;
esac

if [ ! -x "$venv/bin/cargo-zigbuild" ] || [ ! -x "$venv/bin/maturin" ]; then
    say "installing cargo-zigbuild, ziglang and maturin from PyPI into $venv"
    python3 -m venv "$venv" >&2 || say "cannot make a virtual environment (python3-venv)"
    "$venv/bin/python" -m pip install -q --disable-pip-version-check \
        'cargo-zigbuild>=0.20' 'ziglang>=0.13' 'maturin>=1.9,<2' >&2 \
        || say "cannot install cargo-zigbuild, ziglang and maturin: the packages will not be built"
fi
install_cargo_deb
if command -v rustup >/dev/null && ! rustup target list --installed | grep -qx aarch64-unknown-linux-gnu; then
    say "adding the Rust target aarch64-unknown-linux-gnu"
    rustup target add aarch64-unknown-linux-gnu >&2 || say "cannot add aarch64-unknown-linux-gnu: arm64 will not be built"
fi
install_debian
realpath -m "$venv/bin"

//! Finds Chromium for the console's browser test (`tests/console.rs`):
//! with it, `cfg(chromium)` is set and `GOBY_CHROMIUM_PATH` names it; the
//! test is ignored without it, saying why. `GOBY_CHROMIUM` names another
//! build. Likewise tshark for the Wireshark dissector's test
//! (`tests/wireshark.rs`): `cfg(tshark)` and `GOBY_TSHARK_PATH`. Nothing
//! else of the crate depends on them.

use std::path::{Path, PathBuf};

/// Where Debian's package (`.ci/chromium.sh`) and others put it.
const KNOWN: [&str; 4] = [
    "/usr/bin/chromium",
    "/usr/bin/chromium-browser",
    "/usr/lib/chromium/chromium",
    "/snap/bin/chromium",
];

/// Where Debian's tshark package (`.ci/tshark.sh`) puts it.
const TSHARK: &str = "/usr/bin/tshark";

fn main() {
    println!("cargo::rustc-check-cfg=cfg(tshark)");
    if Path::new(TSHARK).is_file() {
        println!("cargo::rerun-if-changed={TSHARK}");
        println!("cargo::rustc-cfg=tshark");
        println!("cargo::rustc-env=GOBY_TSHARK_PATH={TSHARK}");
    }
    println!("cargo::rustc-check-cfg=cfg(chromium)");
    println!("cargo::rerun-if-env-changed=GOBY_CHROMIUM");
    println!("cargo::rerun-if-changed=build.rs");
    let given = std::env::var_os("GOBY_CHROMIUM").map(PathBuf::from);
    let found = given.filter(|p| p.is_file()).or_else(|| {
        KNOWN
            .iter()
            .map(Path::new)
            .find(|p| p.is_file())
            .map(Path::to_path_buf)
    });
    match found {
        Some(path) => {
            // Run again when it is replaced or removed.
            println!("cargo::rerun-if-changed={}", path.display());
            println!("cargo::rustc-cfg=chromium");
            println!("cargo::rustc-env=GOBY_CHROMIUM_PATH={}", path.display());
        }
        None => {
            // Run again when a program is installed where Debian's package
            // puts it (a path that does not exist would make the script,
            // and the crate, build again every time).
            println!("cargo::rerun-if-changed=/usr/bin");
        }
    }
}

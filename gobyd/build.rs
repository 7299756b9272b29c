//! Tells the tests whether a Goby3 build is given (`GOBY3_BUILD`), so that
//! the mixed-fleet test (`tests/goby3_fleet.rs`) runs with it and is
//! reported ignored without it.

fn main() {
    println!("cargo::rustc-check-cfg=cfg(goby3_build)");
    println!("cargo::rerun-if-env-changed=GOBY3_BUILD");
    if std::env::var_os("GOBY3_BUILD").is_some_and(|v| !v.is_empty()) {
        println!("cargo::rustc-cfg=goby3_build");
    }
}

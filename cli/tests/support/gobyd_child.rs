//! A `gobyd` child process for the tests that need the daemon as a program:
//! the test binary runs itself again, with an ignored test of its own as
//! the only test and an environment variable naming the configuration; that
//! test calls [`run_gobyd_named_by`], which runs the `gobyd` library's
//! command line as the `gobyd` binary does.

#![allow(dead_code)]

/// Runs `gobyd --config FILE` (FILE named by the environment variable
/// `var`) until killed, and exits with its status; panics, naming `var`,
/// when it is not set (the test was run by hand).
pub fn run_gobyd_named_by(var: &str) -> ! {
    use clap::Parser;
    let Some(config) = std::env::var_os(var) else {
        panic!("run by the other tests of this file, with {var} naming a configuration");
    };
    let cli = gobyd::command::GobydCli::parse_from([
        std::ffi::OsString::from("gobyd"),
        "--config".into(),
        config,
    ]);
    std::process::exit(i32::from(gobyd::command::run_cli(cli)));
}

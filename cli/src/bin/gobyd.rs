//! `gobyd`: the goby daemon.

fn main() -> std::process::ExitCode {
    goby_cli::gobyd_main()
}

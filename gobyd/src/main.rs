//! `gobyd`: the goby daemon.

fn main() -> std::process::ExitCode {
    gobyd::command::main()
}

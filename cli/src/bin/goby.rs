//! `goby`: the goby shell tool.

fn main() -> std::process::ExitCode {
    goby_cli::goby_main()
}

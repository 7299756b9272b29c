//! The guide's `goby` examples: every console block of `README.md` and
//! `docs/*.md` that calls `goby` (and not `gobyd`, whose blocks
//! `gobyd/tests/guide.rs` runs) is run, and its output compared with the
//! guide's (see the `guide-check` crate for the rules).

use std::path::Path;

#[test]
fn the_guides_goby_examples_print_what_the_guide_shows() {
    let goby = Path::new(env!("CARGO_BIN_EXE_goby"));
    let mut ran = Vec::new();
    for guide in guide_check::guide_files() {
        for line in guide.run_console_blocks(&[("goby", goby)]) {
            ran.push(format!("{}:{line}", guide.name));
        }
    }
    // The tours: the README's and the `goby dccl` chapter's.
    for file in ["README.md", "docs/dccl-shell.md"] {
        assert!(
            ran.iter().any(|r| r.starts_with(&format!("{file}:"))),
            "no console block of {file} ran: {ran:?}"
        );
    }
}

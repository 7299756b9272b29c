//! The guide's links and the files it shows, checked without running any
//! program (the examples are run by `cli/tests/guide.rs` and
//! `gobyd/tests/guide.rs`).

#[test]
fn every_relative_link_of_the_guide_resolves() {
    let checked = guide_check::check_links(&guide_check::guide_files());
    assert!(checked > 50, "only {checked} links found");
}

#[test]
fn blocks_shown_as_files_are_the_committed_files() {
    let files = guide_check::check_shown_files(&guide_check::guide_files());
    assert!(files.len() >= 6, "only {files:?} shown");
}

#[test]
fn every_crate_has_a_readme_whose_links_resolve() {
    let readmes = guide_check::crate_readmes();
    for name in [
        "time",
        "store",
        "protos",
        "dccl",
        "queue",
        "protocol",
        "amac",
        "modemdriver",
        "position",
        "moos",
        "gobyd",
        "cli",
        "python",
    ] {
        let wanted = format!("{name}/README.md");
        assert!(
            readmes.iter().any(|r| r.name == wanted),
            "{wanted} is missing"
        );
    }
    guide_check::check_links(&readmes);
}

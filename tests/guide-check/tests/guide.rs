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
        "channel",
        "moos",
        "gobyd",
        "cli",
        "python",
        "sim",
    ] {
        let wanted = format!("{name}/README.md");
        assert!(
            readmes.iter().any(|r| r.name == wanted),
            "{wanted} is missing"
        );
    }
    guide_check::check_links(&readmes);
}

/// `docs/goby3.md`, the chapter on mixed fleets, links every page's account
/// of what interoperates with Goby3 (a heading naming Goby3 and
/// interoperation), and says "not yet tried" of none of those pages'
/// subjects (the page's file name: `docs/iridium.md` is Iridium).
#[test]
fn the_mixed_fleet_chapter_links_every_account_of_interoperating_with_goby3() {
    let guides = guide_check::guide_files();
    let chapter = guides
        .iter()
        .find(|g| g.name == "docs/goby3.md")
        .expect("docs/goby3.md exists");
    let untried: Vec<String> = chapter
        .text
        .lines()
        .filter(|l| l.to_lowercase().contains("not yet tried"))
        .map(str::to_lowercase)
        .collect();
    let mut accounts = Vec::new();
    let mut failures = String::new();
    for guide in guides.iter().filter(|g| g.name != chapter.name) {
        let Some(file) = guide.name.strip_prefix("docs/") else {
            continue;
        };
        for anchor in guide_check::anchors(&guide.text) {
            if !(anchor.contains("goby3") && anchor.contains("interoperat")) {
                continue;
            }
            let link = format!("({file}#{anchor})");
            if !chapter.text.contains(&link) {
                failures.push_str(&format!("docs/goby3.md does not link {link}\n"));
            }
            let subject = file.trim_end_matches(".md");
            for line in untried.iter().filter(|l| l.contains(subject)) {
                failures.push_str(&format!(
                    "docs/goby3.md says `{line}` while {} tells what interoperates\n",
                    guide.name
                ));
            }
            accounts.push(link);
        }
    }
    assert!(failures.is_empty(), "{failures}");
    assert!(
        accounts.iter().any(|a| a.contains("iridium.md")),
        "no account found: {accounts:?}"
    );
}

/// `CONTRIBUTING.md`'s path of a publication names files that exist,
/// functions those files define, its steps in order, and the number of
/// files it crosses.
#[test]
fn the_path_of_a_publication_names_files_and_functions_that_exist() {
    let root = guide_check::repository_root();
    let text = std::fs::read_to_string(root.join("CONTRIBUTING.md")).expect("CONTRIBUTING.md");
    let start = text
        .find("### The path of a publication")
        .expect("CONTRIBUTING.md has the path of a publication");
    let section = &text[start..];
    let section = &section[..section.find("\n## ").unwrap_or(section.len())];
    let ticked = |cell: &str| -> Vec<String> {
        cell.split('`')
            .skip(1)
            .step_by(2)
            .map(str::to_string)
            .collect()
    };
    let mut files: Vec<String> = Vec::new();
    let mut steps = 0;
    for row in section.lines().filter(|l| l.starts_with("| ")) {
        let cells: Vec<&str> = row.split('|').map(str::trim).collect();
        let Ok(step) = cells[1].parse::<usize>() else {
            continue;
        };
        steps += 1;
        assert_eq!(step, steps, "step {step} is out of order");
        let file = ticked(cells[2]).into_iter().next().expect("a file");
        let code = std::fs::read_to_string(root.join(&file))
            .unwrap_or_else(|e| panic!("step {step}: {file}: {e}"));
        for function in ticked(cells[3]) {
            let name = function.rsplit("::").next().expect("a name");
            let defined = ["(", "<"]
                .iter()
                .any(|after| code.contains(&format!("fn {name}{after}")));
            assert!(defined, "step {step}: {file} defines no function {name}");
        }
        if !files.contains(&file) {
            files.push(file);
        }
    }
    assert!(steps > 10, "only {steps} steps found");
    let told = format!("That is {} files.", files.len());
    assert!(
        section.contains(&told),
        "the page should say \"{told}\" (the files of its table)"
    );
}

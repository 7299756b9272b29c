//! The daemon's core and its edges do not import each other: the core
//! (`src/core/`) takes typed publishes, controls and driver events and
//! returns typed events and replies; the edges (`src/edge/`: JSON, MOOS,
//! MQTT, the mission log) render them, and meet the core only through the
//! shared types of `src/event/` and the composition root (`src/daemon.rs`).
//! CONTRIBUTING.md states the rule; this test reads the sources and fails
//! on a `use` (or path) that crosses it.

use std::path::{Path, PathBuf};

/// Every `.rs` file below `dir`.
fn sources(dir: &Path) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut dirs = vec![dir.to_path_buf()];
    while let Some(d) = dirs.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                dirs.push(path);
            } else if path.extension().is_some_and(|e| e == "rs") {
                found.push(path);
            }
        }
    }
    found.sort();
    found
}

/// The places in the files below `dir` (comments left out) that name
/// module `module` of the crate: a path `crate::module` or
/// `super::module` (at any depth), or `module` in a grouped
/// `use crate::{…}`. Each as `file:line: text`.
fn crossings(dir: &Path, module: &str) -> Vec<String> {
    let paths = [format!("crate::{module}"), format!("super::{module}")];
    let mut found = Vec::new();
    for file in sources(dir) {
        let text = std::fs::read_to_string(&file).unwrap();
        let code: Vec<&str> = text
            .lines()
            .map(|l| l.split("//").next().unwrap_or(""))
            .collect();
        for (n, line) in code.iter().enumerate() {
            if paths.iter().any(|p| line.contains(p.as_str())) {
                found.push(format!("{}:{}: {}", file.display(), n + 1, line.trim()));
            }
        }
        // Grouped imports, over as many lines as they take.
        let mut n = 0;
        while n < code.len() {
            let start = n;
            let mut statement = String::new();
            if code[n].trim_start().starts_with("use crate::{")
                || code[n].trim_start().starts_with("pub(crate) use crate::{")
            {
                while n < code.len() {
                    statement.push_str(code[n]);
                    if code[n].contains(';') {
                        break;
                    }
                    n += 1;
                }
                let names = statement
                    .split(|c: char| !(c.is_alphanumeric() || c == '_' || c == ':'))
                    .filter(|t| !t.is_empty());
                let top: Vec<&str> = names
                    .map(|t| t.trim_start_matches("crate::"))
                    .filter_map(|t| t.split("::").next())
                    .collect();
                if top.contains(&module) {
                    found.push(format!(
                        "{}:{}: {}",
                        file.display(),
                        start + 1,
                        statement.trim()
                    ));
                }
            }
            n += 1;
        }
    }
    found
}

#[test]
fn the_core_does_not_import_its_edges() {
    let core = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/core");
    let found = crossings(&core, "edge");
    assert!(
        found.is_empty(),
        "the core names an edge:\n{}",
        found.join("\n")
    );
}

#[test]
fn the_edges_do_not_import_the_core() {
    let edge = Path::new(env!("CARGO_MANIFEST_DIR")).join("src/edge");
    let found = crossings(&edge, "core");
    assert!(
        found.is_empty(),
        "an edge names the core:\n{}",
        found.join("\n")
    );
}

/// The check itself finds a crossing when there is one.
#[test]
fn a_crossing_is_found() {
    let dir = std::env::temp_dir().join(format!("gobyd-layering-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(dir.join("inner")).unwrap();
    std::fs::write(
        dir.join("inner/a.rs"),
        "// use crate::core::Core; in a comment\nuse crate::core::Core;\nuse crate::{\n    config::X,\n    core::{Core, Y},\n};\nuse crate::{event::Z, corely::W};\n",
    )
    .unwrap();
    let found = crossings(&dir, "core");
    assert_eq!(found.len(), 2, "{found:?}");
    assert!(
        found[0].ends_with("a.rs:2: use crate::core::Core;"),
        "{found:?}"
    );
    assert!(found[1].contains("a.rs:3: use crate::{"), "{found:?}");
    let _ = std::fs::remove_dir_all(&dir);
}

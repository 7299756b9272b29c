//! The guide's "Embedding `dccl`" section (`docs/embedding.md`) shows code
//! taken from this crate:
//! every code line of its Rust blocks is a line of `build.rs`, `src/` or
//! `tests/same_bytes.rs`, which compile and run here.

const GUIDE: &str = include_str!("../../../docs/embedding.md");
const SOURCES: &[&str] = &[
    include_str!("../build.rs"),
    include_str!("../src/lib.rs"),
    include_str!("../src/main.rs"),
    include_str!("same_bytes.rs"),
];

/// Rust code blocks of the guide's section whose heading starts with `heading`.
fn rust_blocks(heading: &str) -> Vec<Vec<&'static str>> {
    let start = GUIDE
        .find(heading)
        .unwrap_or_else(|| panic!("docs/embedding.md has no section {heading:?}"));
    let section = &GUIDE[start + heading.len()..];
    let section = &section[..section.find("\n## ").unwrap_or(section.len())];
    let mut blocks = Vec::new();
    let mut current: Option<Vec<&str>> = None;
    for line in section.lines() {
        match (&mut current, line.trim()) {
            (None, "```rust") => current = Some(Vec::new()),
            (Some(_), "```") => blocks.push(current.take().unwrap()),
            (Some(block), code) => block.push(code),
            (None, _) => {}
        }
    }
    blocks
}

#[test]
fn embedding_section_code_is_compiled_code() {
    let blocks = rust_blocks("## Embedding `dccl`");
    assert!(
        blocks.len() >= 3,
        "expected the dynamic, typed and build.rs blocks"
    );
    let known: Vec<&str> = SOURCES
        .iter()
        .flat_map(|s| s.lines())
        .map(str::trim)
        .collect();
    for line in blocks.iter().flatten() {
        if line.is_empty() || *line == "..." || line.starts_with("//") {
            continue;
        }
        assert!(
            known.contains(line),
            "docs/embedding.md line not found in examples/dccl-typed: {line:?}"
        );
    }
}

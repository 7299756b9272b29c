//! The README's "Writing your own codec" section shows code taken from
//! `examples/user_codec.rs`: every code line of its Rust blocks is a line of
//! the example, which compiles and runs.

const README: &str = include_str!("../../README.md");
const EXAMPLE: &str = include_str!("../examples/user_codec.rs");

#[test]
fn user_codec_section_code_is_the_example_code() {
    let heading = "## Writing your own codec";
    let start = README.find(heading).expect("README has the section");
    let section = &README[start + heading.len()..];
    let section = &section[..section.find("\n## ").unwrap_or(section.len())];
    let known: Vec<&str> = EXAMPLE.lines().map(str::trim).collect();
    let mut in_rust = false;
    let mut checked = 0;
    for line in section.lines().map(str::trim) {
        match (in_rust, line) {
            (false, "```rust") => in_rust = true,
            (true, "```") => in_rust = false,
            (true, code) if code.is_empty() || code == "..." || code.starts_with("//") => {}
            (true, code) => {
                assert!(
                    known.contains(&code),
                    "README line not found in dccl/examples/user_codec.rs: {code:?}"
                );
                checked += 1;
            }
            _ => {}
        }
    }
    assert!(checked >= 5, "the section shows the example's code");
}

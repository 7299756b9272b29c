//! The guide's "Writing your own codec" section (`docs/embedding.md`) shows
//! code taken from `examples/user_codec.rs`: every code line of its Rust and
//! protobuf blocks is a line of the example, which compiles and runs.

const GUIDE: &str = include_str!("../../docs/embedding.md");
const EXAMPLE: &str = include_str!("../examples/user_codec.rs");

#[test]
fn user_codec_section_code_is_the_example_code() {
    let heading = "## Writing your own codec";
    let start = GUIDE
        .find(heading)
        .expect("docs/embedding.md has the section");
    let section = &GUIDE[start + heading.len()..];
    let section = &section[..section.find("\n## ").unwrap_or(section.len())];
    let known: Vec<&str> = EXAMPLE.lines().map(str::trim).collect();
    let mut in_code = false;
    let mut checked = 0;
    for line in section.lines().map(str::trim) {
        match (in_code, line) {
            (false, "```rust" | "```proto") => in_code = true,
            (true, "```") => in_code = false,
            (true, code) if code.is_empty() || code == "..." || code.starts_with("//") => {}
            (true, code) => {
                assert!(
                    known.contains(&code),
                    "docs/embedding.md line not found in dccl/examples/user_codec.rs: {code:?}"
                );
                checked += 1;
            }
            _ => {}
        }
    }
    assert!(checked >= 5, "the section shows the example's code");
}

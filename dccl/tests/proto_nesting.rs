//! `.proto` files nested absurdly deep are refused with the file, line and
//! column, not with a stack overflow; nesting within the limit compiles.

use std::path::PathBuf;

/// A DCCL message whose field option value nests `depth` braces deep.
fn deep_option_source(depth: usize) -> String {
    format!(
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\nmessage Deep {{\n  \
         option (dccl.msg) = {{ id: 1 max_bytes: 8 codec_version: 4 }};\n  \
         optional int32 x = 1 [(dccl.field) = {}{}];\n}}\n",
        "{ a ".repeat(depth),
        "}".repeat(depth)
    )
}

/// A custom option of a recursive message type whose value nests `depth`
/// levels inside the option's own braces (themselves inside `message M {`).
fn recursive_option_source(depth: usize) -> String {
    format!(
        "syntax = \"proto2\";\nimport \"google/protobuf/descriptor.proto\";\n\
         message Node {{ optional Node child = 1; optional int32 v = 2; }}\n\
         extend google.protobuf.MessageOptions {{ optional Node tree = 50001; }}\n\
         message M {{\n  option (tree) = {{ {}v: 1{} }};\n}}\n",
        "child { ".repeat(depth),
        " }".repeat(depth)
    )
}

/// Messages declared inside each other, `depth` levels.
fn nested_messages_source(depth: usize) -> String {
    let mut s = String::from("syntax = \"proto2\";\n");
    for i in 0..depth {
        s.push_str(&format!("message M{i} {{\n"));
    }
    s.push_str("optional int32 x = 1;\n");
    s.push_str(&"}\n".repeat(depth));
    s
}

fn temp_file(name: &str, text: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("dccl-nesting-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn option_value_nested_100000_deep_is_an_error() {
    let source = deep_option_source(100_000);
    let path = temp_file("deep.proto", &source);
    let err = dccl::compile_protos(&[&path], &[] as &[PathBuf])
        .unwrap_err()
        .to_string();
    // Line 5: the message brace and `[` are two levels, the 99th `{ a ` the 101st.
    let column = "  optional int32 x = 1 [(dccl.field) = ".len() + 98 * 4 + 1;
    assert!(
        err.contains(&format!("deep.proto:5:{column}")) && err.contains("nested deeper than 100"),
        "{err}"
    );
    let err = dccl::compile_sources(&[("deep.proto", &source)])
        .unwrap_err()
        .to_string();
    assert!(err.contains(&format!("deep.proto:5:{column}")), "{err}");
    std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
}

#[test]
fn an_imported_file_is_checked_too() {
    let deep = temp_file("imp.proto", &nested_messages_source(500));
    let dir = deep.parent().unwrap();
    let main = dir.join("main.proto");
    std::fs::write(&main, "syntax = \"proto2\";\nimport \"imp.proto\";\n").unwrap();
    let err = dccl::compile_protos(&[&main], &[] as &[PathBuf])
        .unwrap_err()
        .to_string();
    assert!(err.contains("imp.proto:102:"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn nesting_up_to_the_limit_reaches_the_parser() {
    // Within the limit the parser itself answers (here: `a` is no option of
    // dccl.field), without running out of stack on a test thread.
    let path = temp_file("limit.proto", &deep_option_source(98));
    let err = dccl::compile_protos(&[&path], &[] as &[PathBuf])
        .unwrap_err()
        .to_string();
    assert!(!err.contains("nested deeper"), "{err}");
    // Messages nested 20 deep compile.
    let path2 = temp_file("ok.proto", &nested_messages_source(20));
    let pool = dccl::compile_protos(&[&path2], &[] as &[PathBuf]).unwrap();
    assert_eq!(pool.all_messages().count(), 20);
    std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
    std::fs::remove_dir_all(path2.parent().unwrap()).unwrap();
}

#[test]
fn a_recursive_option_value_at_the_limit_compiles_on_a_small_stack() {
    // 98 levels of `child` + the option's braces + `message M {` = 100.
    // The parser recurses once per level; on this test thread's 2 MiB stack
    // it would overflow well before 100 levels of a debug build.
    let pool = dccl::compile_sources(&[("tree.proto", &recursive_option_source(98))]).unwrap();
    assert!(pool.get_message_by_name("M").is_some());
    let err = dccl::compile_sources(&[("tree.proto", &recursive_option_source(99))])
        .unwrap_err()
        .to_string();
    assert!(
        err.contains("tree.proto:6:") && err.contains("nested deeper"),
        "{err}"
    );
    // And from a file, with the same result.
    let path = temp_file("tree.proto", &recursive_option_source(98));
    assert!(dccl::compile_protos(&[&path], &[] as &[PathBuf]).is_ok());
    std::fs::remove_dir_all(path.parent().unwrap()).unwrap();
}

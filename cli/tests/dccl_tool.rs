//! `goby dccl` as users of the reference `dccl` tool use it: its flags and
//! output forms, several files, stitched lines, `omit_id` types, files with
//! helper messages, passphrases from a file or the environment, and
//! definitions too deep to compile. Expected outputs come from the shared
//! field cases or were printed by the reference tool (libdccl 4.2).

mod common;

use std::path::{Path, PathBuf};

use base64::Engine;
use common::*;

const NAV: &str = "protos/proto/goby/example/navigation.proto";

/// A scratch directory of this test process.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-dccl-tool-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn path_str(p: &Path) -> &str {
    p.to_str().expect("UTF-8 path")
}

fn case_proto(case: &str) -> String {
    path_str(&field_case(case).join("case.proto")).to_string()
}

#[test]
fn reference_flags_encode_and_decode_in_every_format() {
    let case = "file-with-non-dccl-helper-message";
    let proto = case_proto(case);
    let input = field_case_file(case, "input.txt");
    let want_hex = field_case_file(case, "expected.hex").trim().to_string();
    let want = hex::decode(&want_hex).unwrap();

    // Raw bytes by default, as the reference tool.
    let out = goby(
        &["dccl", "-e", "-f", &proto, "-m", "fuzzcase.Status"],
        &*input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(out.stdout, want);

    // The long names and the other forms.
    let encoded = |format: &str| {
        let out = goby(
            &[
                "dccl",
                "--encode",
                "--proto_file",
                &proto,
                "--message",
                "fuzzcase.Status",
                "--format",
                format,
            ],
            &*input,
        );
        assert!(out.status.success(), "{format}: {}", stderr_text(&out));
        stdout_text(&out)
    };
    assert_eq!(encoded("hex"), format!("{want_hex}\n"));
    // What the reference prints for the same message.
    assert_eq!(encoded("textformat"), "\"\\004\\006\"\n");
    let b64 = encoded("base64");
    assert_eq!(
        base64::engine::general_purpose::STANDARD
            .decode(b64.trim())
            .unwrap(),
        want
    );

    // Decoding: `|full.Name| text` per message, `-o` without the name.
    for (format, text) in [
        ("bin", None),
        ("hex", Some(format!("{want_hex}\n"))),
        ("textformat", Some(encoded("textformat"))),
        ("base64", Some(b64.clone())),
    ] {
        let stdin = text.map(String::into_bytes).unwrap_or_else(|| want.clone());
        let out = goby(
            &["dccl", "-d", "-f", &proto, "--format", format],
            stdin.clone(),
        );
        assert!(out.status.success(), "{format}: {}", stderr_text(&out));
        assert_eq!(stdout_text(&out), "|fuzzcase.Status| x: 5\n", "{format}");
        let out = goby(
            &["dccl", "--decode", "-o", "-f", &proto, "--format", format],
            stdin,
        );
        assert_eq!(stdout_text(&out), "x: 5\n", "{format}");
    }
}

#[test]
fn reference_encode_without_m_needs_the_type_when_the_file_has_several_and_reads_type_prefixes() {
    let input = "destination: 2 action: GOTO waypoint { x: 120 y: -40 }\n";
    let out = goby(&["dccl", "-e", "-f", NAV, "--format", "hex"], input);
    // The file has two DCCL types (and a helper, Waypoint): a line without
    // its type is refused, naming them; no type is assumed.
    assert_eq!(out.status.code(), Some(1));
    let err = stderr_text(&out);
    assert!(
        bad_lines(&err)[&1].contains(
            "without -m a line must name its type with |full.Name|, as \
             protos/proto/goby/example/navigation.proto defines several DCCL types: \
             goby.example.NavigationReport, goby.example.Command"
        ),
        "{err}"
    );
    assert!(!err.contains("Encoding assuming"), "{err}");
    let by_type = goby(
        &["dccl", "encode", "-f", NAV, "-m", "goby.example.Command"],
        input,
    );
    assert!(by_type.status.success(), "{}", stderr_text(&by_type));
    // `|full.Name|` at the start of a line gives its type.
    let out = goby(
        &["dccl", "-e", "-f", NAV, "--format", "hex"],
        format!("|goby.example.Command| {input}"),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), stdout_text(&by_type));
    // Two types to encode at once is refused.
    let out = goby(
        &[
            "dccl",
            "-e",
            "-f",
            NAV,
            "-m",
            "goby.example.Command",
            "-m",
            "goby.example.NavigationReport",
        ],
        input,
    );
    assert_eq!(out.status.code(), Some(2));
    // No action at all is a usage error.
    let out = goby(&["dccl", "-f", NAV], "");
    assert_eq!(out.status.code(), Some(2));
    // What cannot be done is said plainly.
    for (args, says) in [
        (
            &["dccl", "-a", "-f", NAV, "-l", "libmsgs.so"][..],
            "not supported",
        ),
        (
            &["dccl", "-a", "-f", NAV, "-i", "my.id"][..],
            "dccl.default.id",
        ),
    ] {
        let out = goby(args, "");
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(stderr_text(&out).contains(says), "{}", stderr_text(&out));
    }
    let out = goby(
        &["dccl", "-a", "-H", "-f", NAV, "-i", "dccl.default.id"],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
}

#[test]
fn analyze_hash_only_gives_the_reference_hashes() {
    let proto = vectors_dir().join("vectors.proto");
    let reference = std::fs::read_to_string(vectors_dir().join("hashes.txt")).unwrap();
    let mut want: Vec<String> = reference
        .lines()
        .filter_map(|l| l.split_once(' '))
        .filter(|(name, _)| name.starts_with("vec."))
        .map(|(name, hash)| format!("{name}: {hash}"))
        .collect();
    want.sort();
    let out = goby(&["dccl", "-a", "-H", "-f", path_str(&proto)], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let got: Vec<String> = stdout_text(&out).lines().map(str::to_string).collect();
    assert_eq!(got, want);

    // One type: the hash alone; the subcommand says the same.
    let (name, hash) = reference.lines().next().unwrap().split_once(' ').unwrap();
    for args in [
        &["dccl", "-a", "-H", "-f", path_str(&proto), "-m", name][..],
        &["dccl", "analyze", "-H", "-f", path_str(&proto), "-m", name][..],
    ] {
        let out = goby(args, "");
        assert!(out.status.success(), "{args:?}: {}", stderr_text(&out));
        assert_eq!(stdout_text(&out), format!("{hash}\n"), "{args:?}");
    }

    // The full report is the subcommand's.
    let a = goby(&["dccl", "-a", "-f", path_str(&proto), "-m", name], "");
    let b = goby(&["dccl", "analyze", "-f", path_str(&proto), "-m", name], "");
    assert!(a.status.success());
    assert_eq!(stdout_text(&a), stdout_text(&b));
}

#[test]
fn display_proto_prints_the_definition_as_the_reference_does() {
    let out = goby(&["dccl", "-p", "-f", NAV, "-m", "goby.example.Command"], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    // Printed by the reference tool (libdccl 4.2 on protobuf 3.21).
    let want = r#"Please note that for Google Protobuf versions < 2.5.0, the dccl extensions will not be show below, so you'll need to refer to the original .proto file.
message Command {
  option (.dccl.msg) = {
    id: 125
    max_bytes: 32
    codec_version: 4
  };
  enum Action {
    HOLD = 0;
    GOTO = 1;
    SURFACE = 2;
    ABORT = 3;
  }
  required int32 destination = 1 [(.dccl.field) = {
    in_head: true
    min: 0
    max: 31
  }];
  required .goby.example.Command.Action action = 2;
  repeated .goby.example.Waypoint waypoint = 3 [(.dccl.field) = {
    max_repeat: 3
  }];
  optional string note = 4 [(.dccl.field) = {
    max_length: 10
  }];
}
"#;
    assert_eq!(stdout_text(&out), want);
}

/// Nested types, an enum value option, a oneof, defaults with escapes,
/// standard options beside DCCL ones, reserved numbers and names, extension
/// ranges.
const RICH_PROTO: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package rich;
message Outer {
  option (dccl.msg) = { id: 10 max_bytes: 64 codec_version: 4 unit_system: "si" };
  message Inner {
    enum Kind { A = 0; B = 1 [deprecated = true]; }
    optional Kind kind = 1 [default = B];
    optional double v = 2 [(dccl.field) = { min: -1.5 max: 1e6 precision: 2 units { base_dimensions: "L" } }];
  }
  required Inner inner = 1;
  oneof choice {
    int32 a = 2 [(dccl.field) = { min: 0 max: 7 }];
    bool b = 3;
  }
  optional string s = 4 [default = "a\"b\n", (dccl.field).max_length = 5];
  optional float f = 5 [default = 0.1, (dccl.field) = { min: 0 max: 1 precision: 1 }];
  repeated int32 r = 6 [(dccl.field) = { min: 0 max: 3 max_repeat: 2 }, packed = false];
  optional bytes by = 7 [(dccl.field).max_length = 3, deprecated = true];
  reserved 20, 22 to 25;
  reserved "old";
  extensions 100 to 199;
}
"#;

#[test]
fn display_proto_of_a_rich_definition_is_the_reference_text() {
    let dir = scratch("rich");
    let proto = dir.join("rich.proto");
    std::fs::write(&proto, RICH_PROTO).unwrap();
    let out = goby(&["dccl", "-p", "-f", path_str(&proto)], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    // Printed by the reference tool (libdccl 4.2 on protobuf 3.21).
    let want = r#"Please note that for Google Protobuf versions < 2.5.0, the dccl extensions will not be show below, so you'll need to refer to the original .proto file.
message Outer {
  option (.dccl.msg) = {
    id: 10
    max_bytes: 64
    codec_version: 4
    unit_system: "si"
  };
  message Inner {
    enum Kind {
      A = 0;
      B = 1 [deprecated = true];
    }
    optional .rich.Outer.Inner.Kind kind = 1 [default = B];
    optional double v = 2 [(.dccl.field) = {
      precision: 2
      min: -1.5
      max: 1000000
      units {
        base_dimensions: "L"
      }
    }];
  }
  required .rich.Outer.Inner inner = 1;
  oneof choice {
    int32 a = 2 [(.dccl.field) = {
      min: 0
      max: 7
    }];
    bool b = 3;
  }
  optional string s = 4 [default = "a\"b\n", (.dccl.field) = {
    max_length: 5
  }];
  optional float f = 5 [default = 0.1, (.dccl.field) = {
    precision: 1
    min: 0
    max: 1
  }];
  repeated int32 r = 6 [packed = false, (.dccl.field) = {
    min: 0
    max: 3
    max_repeat: 2
  }];
  optional bytes by = 7 [deprecated = true, (.dccl.field) = {
    max_length: 3
  }];
  extensions 100 to 199;
  reserved 20, 22 to 25;
  reserved "old";
}
"#;
    assert_eq!(stdout_text(&out), want);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn several_proto_files_at_once() {
    let dir = scratch("several");
    let other = dir.join("other.proto");
    std::fs::write(
        &other,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage other;\n\
         message Ping {\n  option (dccl.msg) = { id: 3 max_bytes: 8 codec_version: 4 };\n  \
         optional int32 n = 1 [(dccl.field) = { min: 0 max: 100 }];\n}\n",
    )
    .unwrap();
    let helper = case_proto("file-with-non-dccl-helper-message");
    let other = path_str(&other);
    let ping = goby(
        &["dccl", "encode", "-f", other, "-m", "other.Ping"],
        "n: 42\n",
    );
    assert!(ping.status.success(), "{}", stderr_text(&ping));
    let status = field_case_file("file-with-non-dccl-helper-message", "expected.hex");
    let stdin = format!("{}{}", stdout_text(&ping), status);
    for args in [
        &["dccl", "-d", "--format", "hex", "-f", other, "-f", &helper][..],
        &[
            "dccl", "decode", "-f", other, "--file", &helper, "--out", "text",
        ][..],
    ] {
        let out = goby(args, stdin.clone());
        assert!(out.status.success(), "{args:?}: {}", stderr_text(&out));
        let text = stdout_text(&out);
        let lines: Vec<&str> = text.lines().collect();
        assert_eq!(lines.len(), 2, "{text}");
        assert!(
            lines[0].ends_with("n: 42") && lines[1].ends_with("x: 5"),
            "{text}"
        );
    }
    let out = goby(&["dccl", "-a", "-H", "-f", other, "-f", &helper], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let names: Vec<String> = stdout_text(&out)
        .lines()
        .map(|l| l.split(':').next().unwrap().to_string())
        .collect();
    assert_eq!(names, ["fuzzcase.Status", "other.Ping"]);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn stitched_frame_on_one_line_decodes_every_message() {
    let case = "stitched-frame-on-one-hex-line";
    let proto = case_proto(case);
    let input = field_case_file(case, "input.hex");
    let expected = field_case_file(case, "expected.txt");
    let out = goby(&["dccl", "decode", "-f", &proto], &*input);
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), expected);
    let out = goby(
        &["dccl", "-d", "-o", "--format", "hex", "-f", &proto],
        &*input,
    );
    assert_eq!(stdout_text(&out), expected);

    // The same frame in base64.
    let b64 = base64::engine::general_purpose::STANDARD.encode(hex::decode(input.trim()).unwrap());
    let out = goby(
        &["dccl", "decode", "--format", "base64", "-f", &proto],
        format!("{b64}\n"),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), expected);

    // A byte left over is an error for its line that says where; the
    // messages before it are decoded, the lines after it too.
    let garbage = field_case_file(case, "trailing-garbage.hex");
    let stdin = format!("{}{}", garbage, input);
    let out = goby(&["dccl", "decode", "-f", &proto], stdin);
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(stdout_text(&out), format!("{expected}{expected}"));
    let bad = bad_lines(&stderr_text(&out));
    assert_eq!(bad.keys().copied().collect::<Vec<_>>(), vec![1]);
    assert!(
        bad[&1].starts_with("byte 16: ") && bad[&1].contains("1 byte(s) left undecoded"),
        "{}",
        bad[&1]
    );
}

#[test]
fn omit_id_type_decodes_with_m() {
    let case = "omit-id-decode";
    let proto = case_proto(case);
    let input = field_case_file(case, "input.txt");
    let hex = field_case_file(case, "expected.hex");
    let out = goby(
        &["dccl", "encode", "-f", &proto, "-m", "fuzzcase.Omit"],
        &*input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), hex);
    for args in [
        &["dccl", "decode", "-f", &proto, "-m", "fuzzcase.Omit"][..],
        &[
            "dccl",
            "-d",
            "-o",
            "--format",
            "hex",
            "-f",
            &proto,
            "-m",
            "fuzzcase.Omit",
        ][..],
    ] {
        let out = goby(args, &*hex);
        assert!(out.status.success(), "{args:?}: {}", stderr_text(&out));
        assert_eq!(stdout_text(&out), input, "{args:?}");
    }
    // Without the type there is no id to find it by: an error, not a guess.
    let out = goby(&["dccl", "decode", "-f", &proto], &*hex);
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
}

#[test]
fn files_with_helper_messages_decode_every_valid_type() {
    let case = "file-with-non-dccl-helper-message";
    let proto = case_proto(case);
    let hex = field_case_file(case, "expected.hex");
    let out = goby(&["dccl", "decode", "-f", &proto], &*hex);
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), "x: 5\n");
    let err = stderr_text(&out);
    assert_eq!(
        err.lines()
            .filter(|l| l.contains("fuzzcase.Helper"))
            .count(),
        1,
        "{err}"
    );
    assert!(err.contains("id"), "the reason is given: {err}");

    // encode and analyze need only the type asked for: no warning.
    let out = goby(
        &["dccl", "encode", "-f", &proto, "-m", "fuzzcase.Status"],
        field_case_file(case, "input.txt"),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), hex);
    assert!(out.stderr.is_empty(), "{}", stderr_text(&out));
    let out = goby(
        &["dccl", "analyze", "-f", &proto, "-m", "fuzzcase.Status"],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert!(out.stderr.is_empty(), "{}", stderr_text(&out));
    // Asking for the helper itself is an error naming it.
    let out = goby(
        &["dccl", "analyze", "-f", &proto, "-m", "fuzzcase.Helper"],
        "",
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_text(&out).contains("fuzzcase.Helper"));

    // More kinds of invalid types in one file: an id used twice, bad bounds.
    let dir = scratch("helpers");
    let mixed = dir.join("mixed.proto");
    std::fs::write(
        &mixed,
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package mixed;
message A { option (dccl.msg) = { id: 5 max_bytes: 8 codec_version: 4 };
  optional int32 x = 1 [(dccl.field) = { min: 0 max: 10 }]; }
message B { option (dccl.msg) = { id: 5 max_bytes: 8 codec_version: 4 };
  optional int32 y = 1 [(dccl.field) = { min: 0 max: 10 }]; }
message Reversed { option (dccl.msg) = { id: 6 max_bytes: 8 codec_version: 4 };
  optional int32 z = 1 [(dccl.field) = { min: 10 max: 0 }]; }
message Good { option (dccl.msg) = { id: 7 max_bytes: 8 codec_version: 4 };
  optional int32 w = 1 [(dccl.field) = { min: 0 max: 10 }]; }
"#,
    )
    .unwrap();
    let mixed = path_str(&mixed);
    let a = goby(&["dccl", "encode", "-f", mixed, "-m", "mixed.A"], "x: 3\n");
    let good = goby(
        &["dccl", "encode", "-f", mixed, "-m", "mixed.Good"],
        "w: 4\n",
    );
    assert!(a.status.success() && good.status.success());
    let stdin = format!("{}{}", stdout_text(&a), stdout_text(&good));
    let out = goby(&["dccl", "-d", "--format", "hex", "-f", mixed], stdin);
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(
        stdout_text(&out),
        "|mixed.A| x: 3\n|mixed.Good| w: 4\n",
        "{}",
        stderr_text(&out)
    );
    let err = stderr_text(&out);
    for skipped in ["mixed.B", "mixed.Reversed"] {
        let lines: Vec<&str> = err.lines().filter(|l| l.contains(skipped)).collect();
        assert_eq!(lines.len(), 1, "{skipped} named once: {err}");
    }
    assert!(!err.contains("mixed.Good"), "{err}");
    let _ = std::fs::remove_dir_all(dir);
}

fn encrypted_vectors(n: usize) -> (String, String) {
    let vs: Vec<Vector> = load_vectors("vectors-encrypted.jsonl")
        .into_iter()
        .take(n)
        .collect();
    let hex: String = vs.iter().map(|v| format!("{}\n", v.hex)).collect();
    let text: String = vs.iter().map(|v| format!("{}\n", v.decoded_text)).collect();
    (hex, text)
}

#[test]
fn passphrase_from_a_file_or_the_environment() {
    let proto = vectors_dir().join("vectors.proto");
    let proto = path_str(&proto);
    let (hex, text) = encrypted_vectors(20);
    let dir = scratch("passphrase");
    let file = dir.join("passphrase");
    std::fs::write(&file, format!("{PASSPHRASE}\n")).unwrap();
    let file = path_str(&file);
    let root = workspace_dir();

    let from_file = goby(
        &["dccl", "decode", "-f", proto, "--passphrase-file", file],
        &*hex,
    );
    assert!(from_file.status.success(), "{}", stderr_text(&from_file));
    assert_eq!(stdout_text(&from_file), text);

    let from_env = goby_with_env(
        &root,
        &["dccl", "decode", "-f", proto],
        &*hex,
        &[("DCCL_PASSPHRASE", PASSPHRASE)],
    );
    assert!(from_env.status.success(), "{}", stderr_text(&from_env));
    assert_eq!(stdout_text(&from_env), text);

    // The reference-style flags and encoding take it the same ways.
    let vs: Vec<Vector> = load_vectors("vectors-encrypted.jsonl")
        .into_iter()
        .filter(|v| v.message == "vec.Basic")
        .take(3)
        .collect();
    let input: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
    let want: String = vs.iter().map(|v| format!("{}\n", v.hex)).collect();
    let out = goby_with_env(
        &root,
        &[
            "dccl",
            "-e",
            "--format",
            "hex",
            "-f",
            proto,
            "-m",
            "vec.Basic",
        ],
        &*input,
        &[("DCCL_PASSPHRASE", PASSPHRASE)],
    );
    assert_eq!(stdout_text(&out), want, "{}", stderr_text(&out));
    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            proto,
            "-m",
            "vec.Basic",
            "--passphrase-file",
            file,
        ],
        &*input,
    );
    assert_eq!(stdout_text(&out), want, "{}", stderr_text(&out));

    // The command line wins over the environment.
    let out = goby_with_env(
        &root,
        &["dccl", "decode", "-f", proto, "--passphrase", PASSPHRASE],
        &*hex,
        &[("DCCL_PASSPHRASE", "something else")],
    );
    assert_eq!(stdout_text(&out), text);

    // An empty or missing file, or both options, are refused.
    let empty = dir.join("empty");
    std::fs::write(&empty, "\n").unwrap();
    for args in [
        &[
            "dccl",
            "decode",
            "-f",
            proto,
            "--passphrase-file",
            path_str(&empty),
        ][..],
        &[
            "dccl",
            "decode",
            "-f",
            proto,
            "--passphrase-file",
            "/no/such/file",
        ][..],
        &[
            "dccl",
            "decode",
            "-f",
            proto,
            "--passphrase-file",
            file,
            "--passphrase",
            "x",
        ][..],
    ] {
        let out = goby(args, &*hex);
        assert_eq!(out.status.code(), Some(2), "{args:?}");
        assert!(out.stdout.is_empty());
    }
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn wrong_passphrase_is_reported_as_such() {
    let proto = vectors_dir().join("vectors.proto");
    let (hex, _) = encrypted_vectors(40);
    let out = goby(
        &[
            "dccl",
            "decode",
            "-f",
            path_str(&proto),
            "--passphrase",
            "not the passphrase",
        ],
        &*hex,
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr_text(&out);
    let bad = bad_lines(&err);
    assert!(!bad.is_empty(), "{err}");
    for (line, e) in &bad {
        assert!(e.contains("wrong passphrase"), "line {line}: {e}");
    }
}

/// A `.proto` file whose custom option value nests `depth` messages deep.
fn deep_proto(dir: &Path, depth: usize) -> PathBuf {
    let mut text = String::from(
        "syntax = \"proto2\";\nimport \"google/protobuf/descriptor.proto\";\n\
         import \"dccl/option_extensions.proto\";\npackage deep;\n\
         message R { optional R r = 1; }\n\
         extend google.protobuf.MessageOptions { optional R rr = 50000; }\n\
         message M {\n  option (dccl.msg) = { id: 2 max_bytes: 8 codec_version: 4 };\n  option (rr) = { ",
    );
    text.push_str(&"r { ".repeat(depth));
    text.push_str(&"} ".repeat(depth));
    text.push_str("};\n  optional int32 x = 1 [(dccl.field) = { min: 0 max: 10 }];\n}\n");
    let path = dir.join("deep.proto");
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn options_nested_too_deep_are_an_error_not_a_crash() {
    let dir = scratch("deep");
    let proto = deep_proto(&dir, 100_000);
    let out = goby(
        &["dccl", "analyze", "-f", path_str(&proto), "-m", "deep.M"],
        "",
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr_text(&out));
    let err = stderr_text(&out);
    assert!(err.starts_with("goby: error: "), "{err}");
    assert!(err.contains("deep.proto"), "names the file: {err}");

    let _ = std::fs::remove_dir_all(dir);
}

/// Base64 wrapped at 72 characters with a final line break, as the
/// reference tool's base64 library (libb64) writes each message.
fn libb64(bytes: &[u8]) -> String {
    let text = base64::engine::general_purpose::STANDARD.encode(bytes);
    let mut out = String::new();
    for chunk in text.as_bytes().chunks(72) {
        out.push_str(std::str::from_utf8(chunk).unwrap());
        out.push('\n');
    }
    if text
        .as_bytes()
        .chunks(72)
        .last()
        .is_some_and(|c| c.len() == 72)
    {
        out.push('\n');
    }
    out
}

#[test]
fn base64_wrapped_as_the_reference_writes_it_decodes() {
    let dir = scratch("wrapped");
    let proto = dir.join("long.proto");
    std::fs::write(
        &proto,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage long;\n\
         message Note {\n  option (dccl.msg) = { id: 9 max_bytes: 200 codec_version: 4 };\n  \
         optional string text = 1 [(dccl.field) = { max_length: 150 }];\n}\n",
    )
    .unwrap();
    let proto = path_str(&proto);
    let texts = ["a".repeat(100), "b".repeat(51), "c".repeat(10)];
    let mut wrapped = String::new();
    let mut want = String::new();
    for t in &texts {
        let out = goby(
            &["dccl", "-e", "-f", proto, "-m", "long.Note"],
            format!("text: \"{t}\"\n"),
        );
        assert!(out.status.success(), "{}", stderr_text(&out));
        wrapped.push_str(&libb64(&out.stdout));
        want.push_str(&format!("text: \"{t}\"\n"));
    }
    // 100 characters: over one line of base64; 51: 54 bytes, exactly one
    // full line (then an empty one).
    assert!(wrapped.lines().count() > texts.len(), "{wrapped}");
    assert!(wrapped.contains("\n\n"), "{wrapped}");
    let out = goby(
        &["dccl", "-d", "-o", "--format", "base64", "-f", proto],
        &*wrapped,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), want);

    // The input ending inside a message is an error for the line it started on.
    let first_line = wrapped.lines().next().unwrap();
    let out = goby(
        &["dccl", "decode", "--format", "base64", "-f", proto],
        format!("{first_line}\n"),
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
    let bad = bad_lines(&stderr_text(&out));
    assert!(bad[&1].contains("ends inside a message"), "{:?}", bad);
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn reference_encode_without_m_takes_the_one_dccl_type_not_a_helper() {
    // The first message of the file is a helper, not a DCCL type: the file's
    // one type with a DCCL id is assumed, and lines may still name it.
    let dir = scratch("named-lines");
    let proto = dir.join("helper_first.proto");
    std::fs::write(
        &proto,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage pkg;\n\
         message Helper { optional int32 a = 1; }\n\
         message Name {\n  option (dccl.msg) = { id: 3 max_bytes: 8 codec_version: 4 };\n  \
         required int32 x = 1 [(dccl.field) = { min: 0 max: 10 }];\n}\n",
    )
    .expect("write");
    let out = goby(
        &["dccl", "-e", "-f", path_str(&proto), "--format", "hex"],
        "|pkg.Name| x: 3\n",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), "0603\n");

    // A line without the prefix is of the one DCCL type, pkg.Name, not of
    // the helper: a helper's line is reported, the others encoded.
    let out = goby(
        &["dccl", "-e", "-f", path_str(&proto), "--format", "hex"],
        "x: 5\na: 1\n|pkg.Name| x: 4\n",
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), "0605\n0604\n");
    let err = stderr_text(&out);
    assert!(err.contains("Encoding assuming message: pkg.Name"), "{err}");
    assert!(!err.contains("pkg.Helper"), "{err}");
    assert!(bad_lines(&err)[&2].contains("a"), "{err}");

    // A file of helpers only has nothing to encode.
    let helpers = dir.join("helpers.proto");
    std::fs::write(
        &helpers,
        "syntax = \"proto2\";\npackage pkg;\nmessage Helper { optional int32 a = 1; }\n",
    )
    .expect("write");
    let out = goby(&["dccl", "-e", "-f", path_str(&helpers)], "a: 1\n");
    assert_eq!(out.status.code(), Some(2), "{}", stderr_text(&out));
    assert!(
        stderr_text(&out).contains("defines no message with a DCCL id"),
        "{}",
        stderr_text(&out)
    );
    let _ = std::fs::remove_dir_all(dir);
}

/// The message set with dynamic conditions and libdccl 4.2's (with Lua)
/// answers for it (`dccl/tests/data/dynamic-conditions`).
fn conditions_dir() -> PathBuf {
    workspace_dir().join("dccl/tests/data/dynamic-conditions")
}

#[test]
fn dynamic_conditions_encode_decode_and_analyze() {
    let dir = conditions_dir();
    let proto = dir.join("conditions.proto");
    let inputs = std::fs::read_to_string(dir.join("input.txt")).unwrap();
    let answers = std::fs::read_to_string(dir.join("expected.txt")).unwrap();
    let ty = "goby.test.conditions.Survey";
    // libdccl's encodings of the first Survey instances it encodes (not
    // in MODE_IDLE: there `depth`'s bounds depend on `depth_center`, which
    // an instance may leave unset (150 by default) but which then decodes
    // as 0, so the bytes hold more bits than a decoder reads, libdccl's
    // as this one's, and the rest of the line would be another message).
    let cases: Vec<(String, String, String)> = inputs
        .lines()
        .zip(answers.lines())
        .filter_map(|(input, answer)| {
            let text = input.strip_prefix(&format!("|{ty}|"))?.trim().to_string();
            if text.contains("MODE_IDLE") {
                return None;
            }
            let ok = answer.strip_prefix("ok ")?;
            let mut f = ok.split('\t');
            let (hex, decoded) = (f.next()?.to_string(), f.next()?.to_string());
            (!decoded.starts_with('!')).then_some((text, hex, decoded))
        })
        .take(20)
        .collect();
    assert_eq!(cases.len(), 20);
    let input: String = cases.iter().map(|(t, _, _)| format!("{t}\n")).collect();
    let out = goby(&["dccl", "encode", "-f", path_str(&proto), "-m", ty], input);
    let want: Vec<&str> = cases.iter().map(|(_, h, _)| h.as_str()).collect();
    assert_eq!(stdout_text(&out).lines().collect::<Vec<_>>(), want);

    let hex: String = want.iter().map(|h| format!("{h}\n")).collect();
    let out = goby(&["dccl", "decode", "-f", path_str(&proto)], hex);
    assert!(out.status.success(), "{}", stderr_text(&out));
    for ((_, _, decoded), line) in cases.iter().zip(stdout_text(&out).lines()) {
        assert!(line.ends_with(decoded.as_str()), "{line} / {decoded}");
    }

    // The size report, then the conditions of each field.
    let out = goby(&["dccl", "analyze", "-f", path_str(&proto), "-m", ty], "");
    assert!(out.status.success(), "{}", stderr_text(&out));
    let report = stdout_text(&out);
    for line in [
        "goby.test.conditions.Survey................0-242 {dccl.default4}",
        "--------------------- Dynamic conditions ---------------------",
        "speed required_if: return this.mode == 'MODE_IDLE'",
        "depth min: this.depth_center-100",
        "leg.climb only_if: print(this_index); return root.leg[this_index].kind == 'KIND_HOLD'",
        "payload.spare.gain only_if: this.use == 'USE_ON'",
    ] {
        assert!(report.contains(line), "{line:?} missing from\n{report}");
    }
}

/// Messages whose conditions decide on a value a receiver does not have as
/// the sender had it (an unset embedded message made required, a value the
/// codec changes, a field decoded after the condition).
const NOT_AS_ENCODED: &str = r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package rt;
message Status {
  option (dccl.msg) = { id: 78 max_bytes: 32 codec_version: 4 };
  enum State { IDLE = 0; ABORT = 3; }
  required State state = 1;
  optional int32 code = 2 [(dccl.field) = { min: 0 max: 15
      dynamic_conditions { required_if: "this.state == 'ABORT'" omit_if: "this.state ~= 'ABORT'" } }];
  message Battery {
    required uint32 pct = 1 [(dccl.field) = { min: 0 max: 100 }];
    optional uint32 minutes_left = 2 [(dccl.field) = { min: 0 max: 1000
        dynamic_conditions { required_if: "this.pct < 20" } }];
  }
  optional Battery battery = 3 [(dccl.field) = {
      dynamic_conditions { required_if: "root.state == 'ABORT'" } }];
  optional int32 range = 4 [(dccl.field) = { min: 0 max: 1000 }];
  optional bool flag = 5 [(dccl.field) = {
      dynamic_conditions { required_if: "this.range ~= nil and this.range > 500" } }];
}
message Later {
  option (dccl.msg) = { id: 79 max_bytes: 32 codec_version: 4 };
  message P { required int32 x = 1 [(dccl.field) = { min: 0 max: 9 }]; }
  repeated P p = 1 [(dccl.field) = { max_repeat: 4
      dynamic_conditions { omit_if: "this_index > (root.n or 0)" } }];
  optional uint32 n = 2 [(dccl.field) = { min: 0 max: 4 }];
}
"#;

#[test]
fn encode_warns_about_a_frame_a_receiver_does_not_decode_as_encoded_and_strict_refuses_it() {
    let dir = scratch("not-as-encoded");
    let proto = dir.join("rt.proto");
    std::fs::write(&proto, NOT_AS_ENCODED).unwrap();
    let proto = path_str(&proto);
    let input = "state: ABORT code: 7\n\
                 state: IDLE range: 1800\n\
                 state: ABORT code: 2 battery { pct: 50 } range: 700 flag: true\n\
                 state: IDLE range: 700 flag: false\n";
    // The bytes libdccl 4.2 with Lua writes, each line.
    let out = goby(&["dccl", "encode", "-f", proto, "-m", "rt.Status"], input);
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(
        stdout_text(&out),
        "9c0f0000\n9c0000\n9c450640af01\n9cf40a\n"
    );
    let err = stderr_text(&out);
    for said in [
        // The absent battery, required, is written in 0 bits; a decoder reads 17.
        "line 1: warning: rt.Status: the frame does not decode as it was encoded: a receiver \
         cannot decode it (cannot decode (message rt.Status, field range): message is \
         truncated",
        // 1800 is sent as "not present": the receiver's condition sees nil.
        "line 2: warning: rt.Status: the frame does not decode as it was encoded: a receiver \
         decodes it as state: IDLE, not as it was encoded: the sender codes rt.Status.flag as \
         required (no \"not present\" value), the receiver codes rt.Status.flag as optional",
    ] {
        assert!(err.contains(said), "{said}\n{err}");
    }
    assert!(
        !err.contains("line 3: warning") && !err.contains("line 4"),
        "{err}"
    );

    // Refused with --strict: nothing written for the line, exit status 1.
    let out = goby(
        &["dccl", "encode", "-f", proto, "-m", "rt.Status", "--strict"],
        "state: ABORT code: 7\nstate: IDLE range: 700 flag: false\n",
    );
    assert_eq!(out.status.code(), Some(1), "{}", stderr_text(&out));
    assert_eq!(stdout_text(&out), "9cf40a\n");
    assert!(
        stderr_text(&out).contains(
            "line 1: cannot encode: rt.Status: the frame does not decode as it was encoded: a \
             receiver cannot decode it"
        ),
        "{}",
        stderr_text(&out)
    );

    // A condition reading a later field: named when the type is loaded,
    // and the frame that does not decode as encoded, when it is encoded.
    let out = goby(
        &["dccl", "encode", "-f", proto, "-m", "rt.Later"],
        "p { x: 1 } p { x: 2 } n: 2\n",
    );
    assert_eq!(stdout_text(&out), "9e0a19\n");
    let err = stderr_text(&out);
    assert!(
        err.starts_with(
            "goby: warning: rt.Later.p: dynamic_conditions.omit_if \"this_index > (root.n or 0)\" \
             reads root.n, which is decoded after p:"
        ),
        "{err}"
    );
    assert!(
        err.contains("line 1: warning: rt.Later: the frame does not decode as it was encoded: a receiver reads 2 of its 3 bytes, as p { } p { } n: 0, and the rest as another message"),
        "{err}"
    );
    // Also when the files are read for decoding or sizing.
    let out = goby(&["dccl", "analyze", "-f", proto, "-H"], "");
    assert!(
        stderr_text(&out).contains("goby: warning: rt.Later.p: dynamic_conditions.omit_if"),
        "{}",
        stderr_text(&out)
    );
    let _ = std::fs::remove_dir_all(&dir);
}

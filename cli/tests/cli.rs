//! Behaviour of the `goby` binary: formats, error reports,
//! exit statuses, `analyze`, `bench` and the example message.

mod common;

use std::path::PathBuf;

use base64::Engine;
use common::*;

const B64: base64::engine::GeneralPurpose = base64::engine::general_purpose::STANDARD;

fn vectors_proto() -> String {
    vectors_dir()
        .join("vectors.proto")
        .to_str()
        .expect("UTF-8 path")
        .to_string()
}

/// The first `n` vectors of `vectors.jsonl` of type `message`.
fn some_vectors(message: &str, n: usize) -> Vec<Vector> {
    let v: Vec<Vector> = load_vectors("vectors.jsonl")
        .into_iter()
        .filter(|v| v.message == message)
        .take(n)
        .collect();
    assert_eq!(v.len(), n, "{n} vectors of {message}");
    v
}

/// A scratch directory of this test process.
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("goby-cli-test-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    dir
}

fn lines(s: &str) -> Vec<&str> {
    s.lines().collect()
}

#[test]
fn versions() {
    let out = goby(&["--version"], "");
    assert!(out.status.success());
    assert_eq!(
        stdout_text(&out).trim(),
        format!("goby {}", env!("CARGO_PKG_VERSION"))
    );
}

#[test]
fn usage_errors_exit_2() {
    for args in [
        &[][..],
        &["dccl"][..],
        &["dccl", "frobnicate"][..],
        &["dccl", "encode", "-m", "vec.Basic"][..],
        &["dccl", "encode", "-f", "x.proto"][..],
        &["dccl", "decode", "-f", "x.proto", "--format", "octal"][..],
        &[
            "dccl",
            "bench",
            "-f",
            "x.proto",
            "-m",
            "vec.Basic",
            "--repeat",
            "0",
        ][..],
    ] {
        let out = goby(args, "");
        assert_eq!(out.status.code(), Some(2), "goby {args:?}");
        assert!(!out.stderr.is_empty(), "goby {args:?} says why");
        assert!(
            !stderr_text(&out).contains('\u{1b}'),
            "no colour when stderr is not a terminal"
        );
    }
}

#[test]
fn missing_proto_file_is_a_clear_error() {
    let out = goby(
        &["dccl", "encode", "-f", "no/such/file.proto", "-m", "a.B"],
        "x: 1\n",
    );
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(err.contains("no/such/file.proto"), "{err}");
    assert!(err.contains("no such file"), "{err}");
    assert!(!err.contains("panicked"), "{err}");
    assert!(out.stdout.is_empty());

    let out = goby(&["dccl", "decode", "-f", "no/such/file.proto"], "00\n");
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_text(&out).contains("no such file"));
}

#[test]
fn broken_proto_file_and_unknown_type_exit_2() {
    let dir = scratch("broken");
    let broken = dir.join("broken.proto");
    std::fs::write(
        &broken,
        "syntax = \"proto2\";\nmessage A { required int32 x = ; }\n",
    )
    .expect("write");
    let out = goby(
        &["dccl", "encode", "-f", broken.to_str().unwrap(), "-m", "A"],
        "x: 1\n",
    );
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr_text(&out).contains("broken.proto"),
        "{}",
        stderr_text(&out)
    );

    // The fault is placed at its line and column: a missing ';' at the end of
    // line 5 is found at the start of line 6.
    std::fs::write(
        &broken,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage b;\n\
         message X {\n  required int32 a = 1\n  required int32 b = 2;\n}\n",
    )
    .expect("write");
    let out = goby(
        &["dccl", "encode", "-f", broken.to_str().unwrap(), "-m", "X"],
        "a: 1 b: 2\n",
    );
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(err.contains("broken.proto:6:3: expected ';'"), "{err}");

    let plain = dir.join("plain.proto");
    std::fs::write(
        &plain,
        "syntax = \"proto2\";\npackage p;\nmessage A { optional int32 x = 1; }\n",
    )
    .expect("write");
    let out = goby(&["dccl", "decode", "-f", plain.to_str().unwrap()], "00\n");
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_text(&out).contains("no DCCL message"));

    let out = goby(
        &["dccl", "encode", "-f", plain.to_str().unwrap(), "-m", "p.A"],
        "x: 1\n",
    );
    assert_eq!(out.status.code(), Some(2), "{}", stderr_text(&out));
    assert!(stderr_text(&out).contains("p.A"));

    let out = goby(
        &["dccl", "encode", "-f", &vectors_proto(), "-m", "vec.Nope"],
        "",
    );
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(
        err.contains("vec.Nope") && err.contains("vec.Basic"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(dir);
}

#[test]
fn json_input_gives_the_same_bytes_as_text() {
    let vs = some_vectors("vec.Wide", 10);
    let text: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
    let json: String = vs.iter().map(|v| format!("{}\n", v.input_json)).collect();
    let proto = vectors_proto();
    let a = goby(&["dccl", "encode", "-f", &proto, "-m", "vec.Wide"], text);
    let b = goby(
        &[
            "dccl", "encode", "-f", &proto, "-m", "vec.Wide", "--in", "json",
        ],
        json,
    );
    assert!(a.status.success(), "{}", stderr_text(&a));
    assert!(b.status.success(), "{}", stderr_text(&b));
    assert_eq!(lines(&stdout_text(&a)).len(), vs.len());
    assert_eq!(stdout_text(&a), stdout_text(&b));
}

/// Without `--in`, a line starting with `{` is read as JSON (a text-format
/// message never starts with one) and the others as text, in one input;
/// `--in text` keeps to text and says why such a line fails.
#[test]
fn a_line_starting_with_a_brace_is_json_without_in() {
    let vs = some_vectors("vec.Wide", 6);
    let mixed: String = vs
        .iter()
        .enumerate()
        .map(|(i, v)| match i % 2 {
            0 => format!("  {}\n", v.input_json),
            _ => format!("{}\n", v.input),
        })
        .collect();
    let proto = vectors_proto();
    let out = goby(&["dccl", "encode", "-f", &proto, "-m", "vec.Wide"], mixed);
    assert!(out.status.success(), "{}", stderr_text(&out));
    let want: Vec<&str> = vs.iter().map(|v| v.hex.as_str()).collect();
    assert_eq!(lines(&stdout_text(&out)), want);

    let json = format!("{}\n", vs[0].input_json);
    let out = goby(
        &[
            "dccl", "encode", "-f", &proto, "-m", "vec.Wide", "--in", "text",
        ],
        json.clone(),
    );
    assert_eq!(out.status.code(), Some(1));
    let err = stderr_text(&out);
    assert!(
        err.contains("the line starts with '{' as JSON does: leave out --in text"),
        "{err}"
    );
    // A bad JSON line is told as JSON.
    let out = goby(
        &["dccl", "encode", "-f", &proto, "-m", "vec.Wide"],
        "{\"no_such_field\": 1}\n",
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr_text(&out).contains("cannot parse as JSON vec.Wide"),
        "{}",
        stderr_text(&out)
    );
}

#[test]
fn base64_round_trip() {
    let vs = some_vectors("vec.Nested", 20);
    let proto = vectors_proto();
    let input: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            &proto,
            "-m",
            "vec.Nested",
            "--format",
            "base64",
        ],
        input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let encoded = stdout_text(&out);
    let got = lines(&encoded);
    assert_eq!(got.len(), vs.len());
    for (v, line) in vs.iter().zip(&got) {
        let bytes = B64.decode(line).expect("output is base64");
        assert_eq!(hex::encode(bytes), v.hex, "input {}", v.input);
    }

    let out = goby(
        &[
            "dccl", "decode", "-f", &proto, "--format", "base64", "--out", "json",
        ],
        encoded.clone(),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let pool = pool_for(&vectors_dir().join("vectors.proto"));
    let desc = descriptor(&pool, "vec.Nested");
    let decoded = stdout_text(&out);
    assert_eq!(lines(&decoded).len(), vs.len());
    for (v, line) in vs.iter().zip(lines(&decoded)) {
        let got = from_json(&desc, line).expect("output JSON parses");
        let want = from_json(&desc, &v.decoded_json.to_string()).expect("reference parses");
        assert!(same_message(&got, &want), "hex {}: got {line}", v.hex);
    }
}

#[test]
fn bin_round_trip_with_stitched_messages() {
    let proto = vectors_proto();
    // Encoding several messages of one type as raw bytes: back to back.
    let vs = some_vectors("vec.Basic", 5);
    let input: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            &proto,
            "-m",
            "vec.Basic",
            "--format",
            "bin",
        ],
        input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let want: Vec<u8> = vs
        .iter()
        .flat_map(|v| hex::decode(&v.hex).expect("reference hex"))
        .collect();
    assert_eq!(hex::encode(&out.stdout), hex::encode(&want));

    // Decoding a frame of several messages of several types: one line each.
    let mut mixed = Vec::new();
    for name in [
        "vec.Basic",
        "vec.Lists",
        "vec.Nested",
        "vec.Wide",
        "vec.Special",
    ] {
        mixed.extend(some_vectors(name, 2));
    }
    let frame: Vec<u8> = mixed
        .iter()
        .flat_map(|v| hex::decode(&v.hex).expect("reference hex"))
        .collect();
    let out = goby(
        &[
            "dccl", "decode", "-f", &proto, "--format", "bin", "--out", "json",
        ],
        frame,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let decoded = stdout_text(&out);
    assert_eq!(lines(&decoded).len(), mixed.len(), "{decoded}");
    let pool = pool_for(&vectors_dir().join("vectors.proto"));
    for (v, line) in mixed.iter().zip(lines(&decoded)) {
        let desc = descriptor(&pool, &v.message);
        let got = from_json(&desc, line).expect("output JSON parses");
        let want = from_json(&desc, &v.decoded_json.to_string()).expect("reference parses");
        assert!(same_message(&got, &want), "hex {}: got {line}", v.hex);
    }

    // A frame as gobyd sends it, its identity trailer after the messages:
    // the messages, and no error.
    let mut framed: Vec<u8> = mixed
        .iter()
        .flat_map(|v| hex::decode(&v.hex).expect("reference hex"))
        .collect();
    framed.extend(
        queue::TrailerCodec::new().encode(
            &(0..mixed.len() as u64)
                .map(|n| queue::WireIdentity::new(n, false))
                .collect::<Vec<_>>(),
        ),
    );
    let out = goby(
        &[
            "dccl", "decode", "-f", &proto, "--format", "bin", "--out", "json",
        ],
        framed,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(lines(&stdout_text(&out)).len(), mixed.len());

    // Nothing in, nothing out.
    let out = goby(&["dccl", "decode", "-f", &proto, "--format", "bin"], "");
    assert!(out.status.success());
    assert!(out.stdout.is_empty());
}

#[test]
fn bad_encode_line_is_reported_and_the_others_still_encoded() {
    let vs = some_vectors("vec.Basic", 3);
    let input = format!(
        "{}\n\n{}\ndepth: banana\n{}\ntemp_c: 3\n",
        vs[0].input, vs[1].input, vs[2].input
    );
    let proto = vectors_proto();
    let out = goby(&["dccl", "encode", "-f", &proto, "-m", "vec.Basic"], input);
    assert_eq!(out.status.code(), Some(1));
    let stdout = stdout_text(&out);
    assert_eq!(lines(&stdout), vec![&*vs[0].hex, &*vs[1].hex, &*vs[2].hex]);
    let err = stderr_text(&out);
    let bad = bad_lines(&err);
    assert_eq!(bad.keys().copied().collect::<Vec<_>>(), vec![4, 6], "{err}");
    // A missing required field is named.
    assert!(
        bad[&6].contains("depth") || bad[&6].contains("required"),
        "{err}"
    );
    assert!(!err.contains("panicked"), "{err}");
}

#[test]
fn bad_decode_line_is_reported_and_the_others_still_decoded() {
    let vs = some_vectors("vec.Lists", 2);
    let input = format!("{}\nzz\n7e00\n{}\n", vs[0].hex, vs[1].hex);
    let proto = vectors_proto();
    let out = goby(&["dccl", "decode", "-f", &proto, "--out", "json"], input);
    assert_eq!(out.status.code(), Some(1));
    let stdout = stdout_text(&out);
    assert_eq!(lines(&stdout).len(), 2, "{stdout}");
    let err = stderr_text(&out);
    let bad = bad_lines(&err);
    assert_eq!(bad.keys().copied().collect::<Vec<_>>(), vec![2, 3], "{err}");
    assert!(bad[&2].contains("hex"), "{err}");
}

#[test]
fn bad_input_lines_of_every_kind() {
    let proto = vectors_proto();
    let good = &some_vectors("vec.Basic", 1)[0];
    // Not UTF-8, JSON with trailing text, JSON of the wrong shape.
    let mut input = format!("{}\n", good.input_json).into_bytes();
    input.extend(b"\xff\xfe\n");
    input.extend(format!("{} trailing\n", good.input_json).into_bytes());
    input.extend(b"{\"depth\": \"deep\"}\n");
    input.extend(b"{\"no_such_field\": 1}\n");
    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            &proto,
            "-m",
            "vec.Basic",
            "--in",
            "json",
        ],
        input,
    );
    assert_eq!(out.status.code(), Some(1));
    assert_eq!(lines(&stdout_text(&out)), vec![&*good.hex]);
    let err = stderr_text(&out);
    let bad = bad_lines(&err);
    assert_eq!(
        bad.keys().copied().collect::<Vec<_>>(),
        vec![2, 3, 4, 5],
        "{err}"
    );
    assert!(bad[&2].contains("UTF-8"), "{err}");

    // Garbage in raw mode.
    let out = goby(
        &["dccl", "decode", "-f", &proto, "--format", "bin"],
        vec![0x7e, 0x00, 0x01],
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(
        stderr_text(&out).contains("byte 0"),
        "{}",
        stderr_text(&out)
    );
}

#[test]
fn strict_refuses_out_of_range_values() {
    let proto = vectors_proto();
    let input = "depth: 7000 lat: 0 ok: true req_mode: IDLE\n";
    let out = goby(&["dccl", "encode", "-f", &proto, "-m", "vec.Basic"], input);
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(lines(&stdout_text(&out)).len(), 1);

    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            &proto,
            "-m",
            "vec.Basic",
            "--strict",
        ],
        input,
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
    let err = stderr_text(&out);
    assert!(
        err.starts_with("line 1: ") && err.contains("depth"),
        "{err}"
    );
}

#[test]
fn passphrase_is_needed_to_read_encrypted_messages() {
    let v = load_vectors("vectors-encrypted.jsonl")
        .into_iter()
        .find(|v| v.message == "vec.Wide")
        .expect("an encrypted vec.Wide");
    let proto = vectors_proto();
    let with = goby(
        &[
            "dccl",
            "decode",
            "-f",
            &proto,
            "--out",
            "json",
            "--passphrase",
            PASSPHRASE,
        ],
        format!("{}\n", v.hex),
    );
    assert!(with.status.success(), "{}", stderr_text(&with));
    let without = goby(
        &["dccl", "decode", "-f", &proto, "--out", "json"],
        format!("{}\n", v.hex),
    );
    assert_ne!(stdout_text(&with), stdout_text(&without));
}

#[test]
fn analyze_lists_the_fields_of_vec_basic() {
    let out = goby(
        &["dccl", "analyze", "-f", &vectors_proto(), "-m", "vec.Basic"],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let report = stdout_text(&out);
    for field in [
        "depth", "temp_c", "lat", "heading", "armed", "ok", "mode", "name", "blob", "one_bit",
        "req_mode",
    ] {
        assert!(report.contains(field), "{field} missing from\n{report}");
    }
    // The field lines are those of the reference report.
    let reference =
        std::fs::read_to_string(vectors_dir().join("analyze.txt")).expect("analyze.txt");
    let block: Vec<&str> = reference
        .lines()
        .skip_while(|l| !(l.starts_with("=") && l.contains(" vec.Basic ")))
        .skip(1)
        .take_while(|l| !l.starts_with("==="))
        .filter(|l| l.trim_start().starts_with(|c: char| c.is_ascii_digit()))
        .collect();
    assert_eq!(
        block.len(),
        11,
        "vec.Basic has 11 field lines in analyze.txt"
    );
    let ours: Vec<&str> = report.lines().collect();
    for line in block {
        assert!(ours.contains(&line), "missing line {line:?} in\n{report}");
    }
}

#[test]
fn bench_prints_one_json_object() {
    let vs = some_vectors("vec.Basic", 5);
    let input: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
    let out = goby(
        &[
            "dccl",
            "bench",
            "-f",
            &vectors_proto(),
            "-m",
            "vec.Basic",
            "--repeat",
            "3",
        ],
        input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let text = stdout_text(&out);
    assert_eq!(lines(&text).len(), 1, "{text}");
    let v: serde_json::Value = serde_json::from_str(&text).expect("one JSON object");
    assert_eq!(v["messages"], 5);
    assert!(v["encode_ns_per_msg"].as_f64().expect("number") > 0.0);
    assert!(v["decode_ns_per_msg"].as_f64().expect("number") > 0.0);
    let keys: Vec<&String> = v.as_object().expect("object").keys().collect();
    assert_eq!(keys.len(), 3);

    // JSON input, and no usable input at all.
    let input: String = vs.iter().map(|v| format!("{}\n", v.input_json)).collect();
    let out = goby(
        &[
            "dccl",
            "bench",
            "-f",
            &vectors_proto(),
            "-m",
            "vec.Basic",
            "--repeat",
            "2",
            "--in",
            "json",
        ],
        input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let out = goby(
        &[
            "dccl",
            "bench",
            "-f",
            &vectors_proto(),
            "-m",
            "vec.Basic",
            "--repeat",
            "2",
        ],
        "",
    );
    assert_eq!(out.status.code(), Some(1));
    assert!(out.stdout.is_empty());
}

/// The example shipped in the repository: `protos/examples/navigation_report.txt`.
#[test]
fn example_navigation_report_encodes_and_decodes() {
    let root = workspace_dir();
    let input = std::fs::read_to_string(root.join("protos/examples/navigation_report.txt"))
        .expect("example");
    let proto = "protos/proto/goby/example/navigation.proto";
    let out = goby(
        &[
            "dccl",
            "encode",
            "-f",
            proto,
            "-m",
            "goby.example.NavigationReport",
        ],
        input.clone(),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let encoded = stdout_text(&out);
    let hexes = lines(&encoded);
    assert_eq!(hexes.len(), 2);
    for h in &hexes {
        let bytes = hex::decode(h).expect("hex output");
        assert!(!bytes.is_empty() && bytes.len() <= 32, "{h}");
    }

    // Decoding with the proto directory as include path (and the file given
    // from another working directory) gives the values back to their precision.
    let cli_dir = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let out = goby_in(
        &cli_dir,
        &[
            "dccl",
            "decode",
            "-I",
            "../protos/proto",
            "-f",
            "../protos/proto/goby/example/navigation.proto",
            "--out",
            "json",
        ],
        encoded.clone(),
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let decoded = stdout_text(&out);
    let pool = dccl::compile_protos(&[root.join(proto)], &[] as &[PathBuf]).expect("compiles");
    let desc = descriptor(&pool, "goby.example.NavigationReport");
    assert_eq!(lines(&decoded).len(), 2);
    for (line_in, line_out) in input.lines().zip(lines(&decoded)) {
        let sent = from_text(&desc, line_in).expect("example parses");
        let got = from_json(&desc, line_out).expect("decoded JSON parses");
        let num = |m: &prost_reflect::DynamicMessage, f: &str| {
            m.get_field_by_name(f)
                .and_then(|v| v.as_f64().or(v.as_i32().map(f64::from)))
                .unwrap_or_else(|| panic!("{f} in {line_out}"))
        };
        for (field, tolerance) in [
            ("source", 0.0),
            ("destination", 0.0),
            ("x", 0.05),
            ("y", 0.05),
            ("z", 0.05),
            ("heading", 0.05),
            ("speed", 0.025),
        ] {
            let (a, b) = (num(&sent, field), num(&got, field));
            assert!(
                (a - b).abs() <= tolerance + 1e-9,
                "{field}: sent {a}, got {b}"
            );
        }
        // The time codec sends the time of day only.
        let (a, b) = (num(&sent, "time"), num(&got, "time"));
        assert_eq!((a - b).rem_euclid(86400.0), 0.0, "time: sent {a}, got {b}");
        assert_eq!(
            got.get_field_by_name("veh_class")
                .and_then(|v| v.as_enum_number()),
            Some(1)
        );
        assert_eq!(
            got.get_field_by_name("battery_ok")
                .and_then(|v| v.as_bool()),
            Some(true)
        );
    }
}

#[test]
fn relative_proto_path_from_another_directory() {
    let vs = some_vectors("vec.Basic", 2);
    let input: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
    let out = goby_in(
        &vectors_dir(),
        &["dccl", "encode", "-f", "vectors.proto", "-m", "vec.Basic"],
        input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert_eq!(lines(&stdout_text(&out)), vec![&*vs[0].hex, &*vs[1].hex]);
}

#[test]
fn encode_warns_about_each_value_it_changes() {
    let proto = vectors_proto();
    let input = "depth: 7000 lat: 0 ok: true req_mode: IDLE name: \"abcdefghijk\" heading: nan\n\
                 depth: 7 lat: 0 ok: true req_mode: IDLE\n";
    for args in [
        &["dccl", "encode", "-f", &proto, "-m", "vec.Basic"][..],
        &[
            "dccl",
            "-e",
            "--format",
            "hex",
            "-f",
            &proto,
            "-m",
            "vec.Basic",
        ][..],
    ] {
        let out = goby(args, input);
        assert!(out.status.success(), "{args:?}: {}", stderr_text(&out));
        assert_eq!(lines(&stdout_text(&out)).len(), 2, "both lines are encoded");
        let err = stderr_text(&out);
        let warnings: Vec<&str> = err.lines().collect();
        assert_eq!(warnings.len(), 3, "{err}");
        for (warning, field) in warnings.iter().zip(["depth", "heading", "name"]) {
            assert!(
                warning.starts_with(&format!("line 1: warning: vec.Basic.{field}: ")),
                "{err}"
            );
        }
        assert!(warnings[0].contains("6000"), "the bound is given: {err}");
    }
    // Values within their bounds: no warning.
    let out = goby(
        &["dccl", "encode", "-f", &proto, "-m", "vec.Basic"],
        "depth: 7 lat: 0 ok: true req_mode: IDLE\n",
    );
    assert!(out.status.success() && out.stderr.is_empty());
}

#[test]
fn an_encrypted_message_read_without_its_passphrase_says_to_give_one() {
    let proto = PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("../protos/proto/goby/example/navigation.proto")
        .display()
        .to_string();
    let encode = goby(
        &[
            "dccl",
            "encode",
            "-f",
            &proto,
            "-m",
            "goby.example.Command",
            "--passphrase",
            "secret",
        ],
        "destination: 2 action: GOTO waypoint { x: 120 y: -40 } note: \"survey A\"\n",
    );
    assert!(encode.status.success(), "{}", stderr_text(&encode));
    let without = goby(&["dccl", "decode", "-f", &proto], stdout_text(&encode));
    assert!(!without.status.success(), "{}", stdout_text(&without));
    let err = stderr_text(&without);
    assert!(
        err.contains("if the sender encrypted its messages, give the same --passphrase"),
        "{err}"
    );
}

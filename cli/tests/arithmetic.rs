//! `goby dccl encode/decode/analyze --arithmetic-models FILE`: every vector
//! of `../shared/dccl-vectors/arithmetic/` through the binary (one sender
//! process per message type and one receiver process, in file order), and
//! the analyze title with the definition hash.

mod common;

use std::path::PathBuf;

use common::*;
use prost::Message;
use prost_reflect::DynamicMessage;

fn arithmetic_dir() -> PathBuf {
    vectors_dir().join("arithmetic")
}

fn path(p: PathBuf) -> String {
    p.to_str().expect("UTF-8 path").to_string()
}

struct ArithVector {
    message: String,
    input: String,
    hex: String,
    decoded_json: serde_json::Value,
}

fn vectors() -> Vec<ArithVector> {
    let text = std::fs::read_to_string(arithmetic_dir().join("vectors.jsonl")).expect("vectors");
    text.lines()
        .filter(|l| !l.trim().is_empty())
        .map(|l| {
            let v: serde_json::Value = serde_json::from_str(l).expect("JSON line");
            ArithVector {
                message: v["message"].as_str().unwrap().to_string(),
                input: v["input"].as_str().unwrap().to_string(),
                hex: v["hex"].as_str().unwrap().to_string(),
                decoded_json: v["decoded_json"].clone(),
            }
        })
        .collect()
}

#[test]
fn arithmetic_vectors_through_the_binary() {
    let proto = path(arithmetic_dir().join("arithmetic.proto"));
    let models = path(arithmetic_dir().join("models.txt"));
    let all = vectors();
    assert_eq!(all.len(), 300);

    // Encode: one process per message type, its lines in file order.
    for message in ["arith.Telemetry", "arith.Counts"] {
        let of_type: Vec<&ArithVector> = all.iter().filter(|v| v.message == message).collect();
        let input: String = of_type.iter().map(|v| format!("{}\n", v.input)).collect();
        let out = goby(
            &[
                "dccl",
                "encode",
                "-f",
                &proto,
                "-m",
                message,
                "--arithmetic-models",
                &models,
            ],
            input,
        );
        assert!(out.status.success(), "{}", stderr_text(&out));
        let got: Vec<String> = stdout_text(&out).lines().map(str::to_string).collect();
        let want: Vec<String> = of_type.iter().map(|v| v.hex.clone()).collect();
        assert_eq!(got, want, "{message}");
    }

    // Decode: one process, every line in file order.
    let input: String = all.iter().map(|v| format!("{}\n", v.hex)).collect();
    let out = goby(
        &[
            "dccl",
            "decode",
            "-f",
            &proto,
            "--arithmetic-models",
            &models,
            "--out",
            "json",
        ],
        input,
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let pool = dccl::compile_protos(
        &[arithmetic_dir().join("arithmetic.proto")],
        &[] as &[PathBuf],
    )
    .expect("compiles");
    let text = stdout_text(&out);
    let got: Vec<&str> = text.lines().collect();
    assert_eq!(got.len(), all.len());
    for (n, (line, v)) in got.iter().zip(&all).enumerate() {
        let desc = pool.get_message_by_name(&v.message).unwrap();
        let parse = |json: &str| {
            let mut de = serde_json::Deserializer::from_str(json);
            DynamicMessage::deserialize(desc.clone(), &mut de).expect("JSON message")
        };
        let ours = parse(line);
        let want = parse(&v.decoded_json.to_string());
        assert_eq!(
            ours.encode_to_vec(),
            want.encode_to_vec(),
            "vector {n}: {line}"
        );
    }
}

#[test]
fn without_the_models_the_codec_reports_the_missing_model() {
    let proto = path(arithmetic_dir().join("arithmetic.proto"));
    let out = goby(
        &["dccl", "analyze", "-f", &proto, "-m", "arith.Telemetry"],
        "",
    );
    assert!(!out.status.success());
    let err = stderr_text(&out);
    assert!(
        err.contains("arith.Telemetry") && err.contains("\"delta\""),
        "{err}"
    );

    let bad = std::env::temp_dir().join(format!("goby-arith-bad-{}.txt", std::process::id()));
    std::fs::write(
        &bad,
        "name: \"x\" value_bound: 0 frequency: 0 value_bound: 1\n",
    )
    .unwrap();
    let out = goby(
        &[
            "dccl",
            "analyze",
            "-f",
            &proto,
            "-m",
            "arith.Telemetry",
            "--arithmetic-models",
            &path(bad.clone()),
        ],
        "",
    );
    std::fs::remove_file(&bad).ok();
    assert!(!out.status.success());
    assert!(
        stderr_text(&out).contains("nonzero"),
        "{}",
        stderr_text(&out)
    );
}

#[test]
fn analyze_shows_the_arithmetic_field_and_the_hash() {
    let proto = path(arithmetic_dir().join("arithmetic.proto"));
    let models = path(arithmetic_dir().join("models.txt"));
    let out = goby(
        &[
            "dccl",
            "analyze",
            "-f",
            &proto,
            "-m",
            "arith.Telemetry",
            "--arithmetic-models",
            &models,
        ],
        "",
    );
    assert!(out.status.success(), "{}", stderr_text(&out));
    let report = stdout_text(&out);
    let title = report.lines().next().unwrap();
    assert!(title.contains("40: arith.Telemetry {0x"), "{title}");
    assert!(
        report.contains("1. dx[8]") && report.contains("{dccl.arithmetic}"),
        "{report}"
    );

    // The title line of vec.Basic is the reference's, hash included.
    let out = goby(
        &[
            "dccl",
            "analyze",
            "-f",
            &path(vectors_dir().join("vectors.proto")),
            "-m",
            "vec.Basic",
        ],
        "",
    );
    let reference = std::fs::read_to_string(vectors_dir().join("analyze.txt")).unwrap();
    let want = reference
        .lines()
        .find(|l| l.contains(" vec.Basic "))
        .unwrap();
    assert_eq!(stdout_text(&out).lines().next().unwrap(), want);
}

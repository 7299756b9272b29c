//! Every reference vector of `../shared/dccl-vectors` through the `goby`
//! binary: one `goby dccl encode` per message type (all of that type's
//! inputs on standard input), one `goby dccl decode` per file.

mod common;

use common::*;

/// Input form of `encode`.
#[derive(Clone, Copy)]
enum In {
    Text,
    Json,
}

/// Encodes every vector of `jsonl` (types defined in `proto`) and compares
/// each output line with the reference hex.
fn check_encode(proto: &str, jsonl: &str, form: In, passphrase: Option<&str>) {
    let proto_path = vectors_dir().join(proto);
    let proto_arg = proto_path.to_str().expect("UTF-8 path");
    let vectors = load_vectors(jsonl);
    let mut failures = Failures::default();
    for (message, group) in by_message(&vectors) {
        let mut args = vec!["dccl", "encode", "-f", proto_arg, "-m", &message];
        if let In::Json = form {
            args.extend(["--in", "json"]);
        }
        if let Some(p) = passphrase {
            args.extend(["--passphrase", p]);
        }
        let input: String = group
            .iter()
            .map(|v| match form {
                In::Text => format!("{}\n", v.input),
                In::Json => format!("{}\n", v.input_json),
            })
            .collect();
        let out = goby(&args, input);
        let stdout = stdout_text(&out);
        let stderr = stderr_text(&out);
        let results = align(group.len(), &stdout, &stderr);
        let all_ok = results.iter().all(Result::is_ok);
        if all_ok && out.status.code() != Some(0) {
            failures.check(Some(format!(
                "{message}: exit status {:?} with every line encoded; stderr: {stderr}",
                out.status.code()
            )));
        }
        if !all_ok && out.status.code() != Some(1) {
            failures.check(Some(format!(
                "{message}: exit status {:?} (expected 1) with bad lines",
                out.status.code()
            )));
        }
        for (v, got) in group.iter().zip(results) {
            let failure = match got {
                Ok(hex) if hex == v.hex => None,
                Ok(hex) => Some(hex),
                Err(e) => Some(e),
            };
            failures.check(failure.map(|got| {
                format!(
                    "{jsonl} line {}: {message}\n  input {}\n  want  {}\n  got   {got}",
                    v.line,
                    match form {
                        In::Text => &v.input,
                        In::Json => &v.input_json,
                    },
                    v.hex
                )
            }));
        }
    }
    failures.assert_none(&format!("encode {jsonl}"));
}

/// Output form of `decode`.
#[derive(Clone, Copy)]
enum Out {
    Text,
    Json,
}

/// Decodes every vector's hex of `jsonl` in one process and compares each
/// output line, as values, with the reference decoded message.
fn check_decode(proto: &str, jsonl: &str, form: Out, passphrase: Option<&str>) {
    let proto_path = vectors_dir().join(proto);
    let proto_arg = proto_path.to_str().expect("UTF-8 path");
    let pool = pool_for(&proto_path);
    let vectors = load_vectors(jsonl);
    let mut args = vec!["dccl", "decode", "-f", proto_arg];
    args.extend(match form {
        Out::Text => ["--out", "text"],
        Out::Json => ["--out", "json"],
    });
    if let Some(p) = passphrase {
        args.extend(["--passphrase", p]);
    }
    let input: String = vectors.iter().map(|v| format!("{}\n", v.hex)).collect();
    let out = goby(&args, input);
    let stdout = stdout_text(&out);
    let stderr = stderr_text(&out);
    let results = align(vectors.len(), &stdout, &stderr);
    let mut failures = Failures::default();
    let all_ok = results.iter().all(Result::is_ok);
    if all_ok && out.status.code() != Some(0) {
        failures.check(Some(format!(
            "exit status {:?} with every line decoded; stderr: {stderr}",
            out.status.code()
        )));
    }
    for (v, got) in vectors.iter().zip(results) {
        let desc = descriptor(&pool, &v.message);
        let (want_text, want) = match form {
            Out::Json => {
                let s = v.decoded_json.to_string();
                let m = from_json(&desc, &s);
                (s, m)
            }
            Out::Text => (v.decoded_text.clone(), from_text(&desc, &v.decoded_text)),
        };
        let want = want.unwrap_or_else(|e| {
            panic!(
                "{jsonl} line {}: reference decoded value does not parse: {e}",
                v.line
            )
        });
        let failure = match got {
            Ok(line) => {
                let parsed = match form {
                    Out::Json => from_json(&desc, &line),
                    Out::Text => from_text(&desc, &line),
                };
                match parsed {
                    // Text output is also the reference's exact one-line form.
                    Ok(_) if matches!(form, Out::Text) && line != v.decoded_text => {
                        Some(format!("{line} (not the reference's text)"))
                    }
                    Ok(m) if same_message(&m, &want) => None,
                    Ok(_) => Some(line),
                    Err(e) => Some(format!("{line} (does not parse as {}: {e})", v.message)),
                }
            }
            Err(e) => Some(e),
        };
        failures.check(failure.map(|got| {
            format!(
                "{jsonl} line {}: {}\n  hex   {}\n  want  {want_text}\n  got   {got}",
                v.line, v.message, v.hex
            )
        }));
    }
    failures.assert_none(&format!("decode {jsonl}"));
}

#[test]
fn encode_text_vectors() {
    check_encode("vectors.proto", "vectors.jsonl", In::Text, None);
}

#[test]
fn encode_json_vectors() {
    check_encode("vectors.proto", "vectors.jsonl", In::Json, None);
}

#[test]
fn decode_vectors_to_json() {
    check_decode("vectors.proto", "vectors.jsonl", Out::Json, None);
}

#[test]
fn decode_vectors_to_text() {
    check_decode("vectors.proto", "vectors.jsonl", Out::Text, None);
}

#[test]
fn encode_text_legacy_vectors() {
    check_encode("legacy.proto", "legacy.jsonl", In::Text, None);
}

#[test]
fn encode_json_legacy_vectors() {
    check_encode("legacy.proto", "legacy.jsonl", In::Json, None);
}

#[test]
fn decode_legacy_vectors_to_json() {
    check_decode("legacy.proto", "legacy.jsonl", Out::Json, None);
}

#[test]
fn decode_legacy_vectors_to_text() {
    check_decode("legacy.proto", "legacy.jsonl", Out::Text, None);
}

#[test]
fn encode_encrypted_vectors() {
    check_encode(
        "vectors.proto",
        "vectors-encrypted.jsonl",
        In::Text,
        Some(PASSPHRASE),
    );
}

#[test]
fn encode_json_encrypted_vectors() {
    check_encode(
        "vectors.proto",
        "vectors-encrypted.jsonl",
        In::Json,
        Some(PASSPHRASE),
    );
}

#[test]
fn decode_encrypted_vectors_to_json() {
    check_decode(
        "vectors.proto",
        "vectors-encrypted.jsonl",
        Out::Json,
        Some(PASSPHRASE),
    );
}

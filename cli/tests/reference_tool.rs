//! `goby dccl` against the reference `dccl` tool (libdccl 4.2's
//! `src/apps/dccl`), when one is given: the same command lines must print the
//! same standard output.
//!
//! ```text
//! DCCL_REFERENCE_TOOL=/path/to/dccl cargo test -p goby-cli --test reference_tool -- --nocapture
//! ```
//!
//! Without `DCCL_REFERENCE_TOOL` the test prints that it is skipped. Compared:
//! `-a`, `-a -H` and `-p` for the shared vectors' definitions, the example
//! messages and every field case; `-e` in the
//! `hex`, `textformat` and `bin` forms for every vector input; `-d` of every
//! vector, with and without `-o`, from hex and from text-format byte strings.
//! (base64 is left out: the reference builds it only with libb64.)

mod common;

use std::path::{Path, PathBuf};

use common::*;

fn reference_tool() -> Option<PathBuf> {
    let path = PathBuf::from(std::env::var_os("DCCL_REFERENCE_TOOL")?);
    assert!(
        path.is_file(),
        "DCCL_REFERENCE_TOOL={} is not a file",
        path.display()
    );
    Some(path)
}

/// Standard output of `exe args < stdin` (status ignored: the reference
/// tool exits 0 on most errors).
fn run(exe: &Path, args: &[&str], stdin: &[u8]) -> Vec<u8> {
    let out = assert_cmd::Command::new(exe)
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .env_remove("DCCL_PASSPHRASE")
        .write_stdin(stdin.to_vec())
        .output()
        .unwrap_or_else(|e| panic!("{} runs: {e}", exe.display()));
    out.stdout
}

/// Compares the two tools on one command line; returns a description of the
/// first difference.
fn compare(reference: &Path, args: &[&str], stdin: &[u8]) -> Option<String> {
    let theirs = run(reference, args, stdin);
    let mut goby_args = vec!["dccl"];
    goby_args.extend_from_slice(args);
    let ours = run(Path::new(env!("CARGO_BIN_EXE_goby")), &goby_args, stdin);
    if theirs == ours {
        return None;
    }
    let (t, o) = (
        String::from_utf8_lossy(&theirs),
        String::from_utf8_lossy(&ours),
    );
    let line = t
        .lines()
        .zip(o.lines())
        .position(|(a, b)| a != b)
        .unwrap_or_else(|| t.lines().count().min(o.lines().count()));
    Some(format!(
        "dccl {}: output line {}: reference {:?}, goby {:?}",
        args.join(" "),
        line + 1,
        t.lines().nth(line).unwrap_or("<end>"),
        o.lines().nth(line).unwrap_or("<end>")
    ))
}

#[test]
#[ignore = "needs DCCL_REFERENCE_TOOL, the reference dccl tool (libdccl 4.2): cargo test -p goby-cli --test reference_tool -- --ignored"]
fn same_output_as_the_reference_tool() {
    let Some(reference) = reference_tool() else {
        panic!("set DCCL_REFERENCE_TOOL to the reference dccl tool (libdccl 4.2) to compare");
    };
    let mut failures = Failures::default();
    let vectors = vectors_dir();
    let mut protos: Vec<PathBuf> = vec![
        vectors.join("vectors.proto"),
        vectors.join("legacy.proto"),
        workspace_dir().join("protos/proto/goby/example/navigation.proto"),
    ];
    let cases = std::fs::read_dir(field_case("omit-id-decode").parent().unwrap()).unwrap();
    let mut cases: Vec<PathBuf> = cases
        .map(|e| e.unwrap().path().join("case.proto"))
        .filter(|p| p.is_file())
        .collect();
    cases.sort();
    protos.extend(cases);
    for proto in &protos {
        let proto = proto.to_str().expect("UTF-8 path");
        for action in [&["-a"][..], &["-a", "-H"][..], &["-p"][..]] {
            // A file with no valid type at all: the reference prints the
            // note line of -p and nothing else, goby says so as an error.
            if action == ["-p"] && proto.contains("repeated-field-in-head") {
                continue;
            }
            let mut args = action.to_vec();
            args.extend(["-f", proto]);
            failures.check(compare(&reference, &args, b""));
        }
    }

    for (file, proto) in [
        ("vectors.jsonl", "vectors.proto"),
        ("legacy.jsonl", "legacy.proto"),
    ] {
        let proto = vectors.join(proto);
        let proto = proto.to_str().expect("UTF-8 path");
        let all = load_vectors(file);
        for (message, vs) in by_message(&all) {
            let input: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
            for format in ["hex", "textformat", "bin"] {
                let args = ["-e", "-f", proto, "-m", &message, "--format", format];
                failures.check(compare(&reference, &args, input.as_bytes()));
            }
        }
        let hex: String = all.iter().map(|v| format!("{}\n", v.hex)).collect();
        for omit in [&[][..], &["-o"][..]] {
            let mut args = vec!["-d", "-f", proto, "--format", "hex"];
            args.extend_from_slice(omit);
            failures.check(compare(&reference, &args, hex.as_bytes()));
        }
        // Text-format byte strings as the reference writes them.
        let mut text = Vec::new();
        for (message, vs) in by_message(&all) {
            let input: String = vs.iter().map(|v| format!("{}\n", v.input)).collect();
            let args = ["-e", "-f", proto, "-m", &message, "--format", "textformat"];
            text.extend(run(&reference, &args, input.as_bytes()));
        }
        let args = ["-d", "-f", proto, "--format", "textformat"];
        failures.check(compare(&reference, &args, &text));
    }
    failures.assert_none("goby dccl against the reference dccl tool");
    println!(
        "{} command lines print the same as the reference tool",
        failures.checked
    );
}

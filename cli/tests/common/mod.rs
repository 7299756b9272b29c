//! Helpers shared by the `goby` command-line tests.

#![allow(dead_code)]

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Output;

use prost_reflect::{DescriptorPool, DynamicMessage, MessageDescriptor, ReflectMessage, Value};

/// The shared wire-compatibility vectors.
pub fn vectors_dir() -> PathBuf {
    // ../shared beside the project when present, else the copy committed
    // with the dccl crate's tests.
    let shared = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/dccl-vectors"
    ));
    let dir = if shared.is_dir() {
        shared
    } else {
        PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../dccl/tests/data/dccl-vectors"
        ))
    };
    assert!(
        dir.join("README.md").is_file(),
        "the DCCL vectors are missing: expected them in {}",
        dir.display()
    );
    dir
}

/// Root of the workspace.
pub fn workspace_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

/// Passphrase of `vectors-encrypted.jsonl`.
pub const PASSPHRASE: &str = "correct horse battery staple";

/// One reference vector.
#[derive(Debug, Clone)]
pub struct Vector {
    /// Line in its `.jsonl` file (from 1).
    pub line: usize,
    /// Full name of the message type.
    pub message: String,
    /// The input in text format.
    pub input: String,
    /// The input as one line of proto3 JSON.
    pub input_json: String,
    /// Expected encoding, lower-case hex.
    pub hex: String,
    /// Expected decoded value, proto3 JSON.
    pub decoded_json: serde_json::Value,
    /// Expected decoded value, text format.
    pub decoded_text: String,
}

/// Reads every vector of a `.jsonl` file of the vectors directory.
pub fn load_vectors(file: &str) -> Vec<Vector> {
    let path = vectors_dir().join(file);
    let text = std::fs::read_to_string(&path)
        .unwrap_or_else(|e| panic!("cannot read {}: {e}", path.display()));
    let mut out = Vec::new();
    for (i, line) in text.lines().enumerate() {
        if line.trim().is_empty() {
            continue;
        }
        let v: serde_json::Value = serde_json::from_str(line)
            .unwrap_or_else(|e| panic!("{file} line {}: not JSON: {e}", i + 1));
        let field = |name: &str| {
            v[name]
                .as_str()
                .unwrap_or_else(|| panic!("{file} line {}: no string {name}", i + 1))
                .to_string()
        };
        out.push(Vector {
            line: i + 1,
            message: field("message"),
            input: field("input"),
            input_json: v["input_json"].to_string(),
            hex: field("hex"),
            decoded_json: v["decoded_json"].clone(),
            decoded_text: field("decoded_text"),
        });
    }
    assert!(!out.is_empty(), "{file} holds no vector");
    out
}

/// The vectors grouped by message type, file order kept within each group.
pub fn by_message(vectors: &[Vector]) -> BTreeMap<String, Vec<Vector>> {
    let mut map: BTreeMap<String, Vec<Vector>> = BTreeMap::new();
    for v in vectors {
        map.entry(v.message.clone()).or_default().push(v.clone());
    }
    map
}

/// Runs `goby` with `args`, feeding `stdin`; RUST_BACKTRACE unset.
pub fn goby(args: &[&str], stdin: impl Into<Vec<u8>>) -> Output {
    goby_in(&workspace_dir(), args, stdin)
}

/// Runs `goby` in the directory `dir`.
pub fn goby_in(dir: &Path, args: &[&str], stdin: impl Into<Vec<u8>>) -> Output {
    goby_with_env(dir, args, stdin, &[])
}

/// Runs `goby` in the directory `dir` with the environment variables `env`
/// set (and neither RUST_BACKTRACE nor DCCL_PASSPHRASE unless given).
pub fn goby_with_env(
    dir: &Path,
    args: &[&str],
    stdin: impl Into<Vec<u8>>,
    env: &[(&str, &str)],
) -> Output {
    let mut cmd = assert_cmd::Command::new(env!("CARGO_BIN_EXE_goby"));
    cmd.current_dir(dir)
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .env_remove("DCCL_PASSPHRASE");
    for (k, v) in env {
        cmd.env(k, v);
    }
    cmd.write_stdin(stdin.into()).output().expect("goby runs")
}

/// One folder of the DCCL field cases (`../shared/dccl-field-cases`, or the
/// committed copy `dccl/tests/data/field-cases`).
pub fn field_case(name: &str) -> PathBuf {
    // ../shared beside the project when present, else the copy committed
    // with the dccl crate's tests.
    let shared = PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../shared/dccl-field-cases"
    ));
    let base = if shared.is_dir() {
        shared
    } else {
        PathBuf::from(concat!(
            env!("CARGO_MANIFEST_DIR"),
            "/../dccl/tests/data/field-cases"
        ))
    };
    let dir = base.join(name);
    assert!(
        dir.join("case.proto").is_file(),
        "the DCCL field cases are missing: expected {}",
        dir.display()
    );
    dir
}

/// A file of a field case, as text.
pub fn field_case_file(case: &str, file: &str) -> String {
    let path = field_case(case).join(file);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// Standard output as text.
pub fn stdout_text(out: &Output) -> String {
    String::from_utf8(out.stdout.clone()).expect("stdout is UTF-8")
}

/// Standard error as text.
pub fn stderr_text(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Input line numbers reported as bad on standard error (`line N: ...`),
/// with their messages; warnings (`line N: warning: ...`) are not.
pub fn bad_lines(stderr: &str) -> BTreeMap<usize, String> {
    let mut map = BTreeMap::new();
    for l in stderr.lines() {
        if let Some(rest) = l.strip_prefix("line ") {
            if let Some((n, msg)) = rest.split_once(": ") {
                if msg.starts_with("warning: ") {
                    continue;
                }
                if let Ok(n) = n.parse() {
                    map.insert(n, msg.to_string());
                }
            }
        }
    }
    map
}

/// Pairs each input line (numbered from 1) with its output line: lines
/// reported bad on standard error have no output. Returns, per input, either
/// its output line or the error reported for it.
pub fn align(count: usize, stdout: &str, stderr: &str) -> Vec<Result<String, String>> {
    let bad = bad_lines(stderr);
    let mut outputs = stdout.lines();
    (1..=count)
        .map(|n| match bad.get(&n) {
            Some(e) => Err(format!("reported bad: {e}")),
            None => outputs
                .next()
                .map(str::to_string)
                .ok_or_else(|| format!("no output (stderr: {})", stderr.trim())),
        })
        .collect()
}

/// Compiles a `.proto` file of the vectors directory for comparisons.
pub fn pool_for(proto: &Path) -> DescriptorPool {
    dccl::compile_protos(&[proto], &[] as &[PathBuf])
        .unwrap_or_else(|e| panic!("{} compiles: {e}", proto.display()))
}

/// Descriptor of `name` in `pool`.
pub fn descriptor(pool: &DescriptorPool, name: &str) -> MessageDescriptor {
    pool.get_message_by_name(name)
        .unwrap_or_else(|| panic!("{name} is in the pool"))
}

/// Parses proto3 JSON into a message of type `desc`.
pub fn from_json(desc: &MessageDescriptor, json: &str) -> Result<DynamicMessage, String> {
    let mut de = serde_json::Deserializer::from_str(json);
    let msg = DynamicMessage::deserialize(desc.clone(), &mut de).map_err(|e| e.to_string())?;
    de.end().map_err(|e| e.to_string())?;
    Ok(msg)
}

/// Parses text format into a message of type `desc`.
pub fn from_text(desc: &MessageDescriptor, text: &str) -> Result<DynamicMessage, String> {
    DynamicMessage::parse_text_format(desc.clone(), text).map_err(|e| e.to_string())
}

/// Same fields set with the same values; doubles equal within 1e-9
/// relative, floats within 1e-6 relative (the reference prints floats with
/// float precision).
pub fn same_message(a: &DynamicMessage, b: &DynamicMessage) -> bool {
    if a.descriptor() != b.descriptor() {
        return false;
    }
    let fa: Vec<_> = a.fields().collect();
    let fb: Vec<_> = b.fields().collect();
    fa.len() == fb.len()
        && fa
            .iter()
            .zip(&fb)
            .all(|((f1, v1), (f2, v2))| f1.number() == f2.number() && same_value(v1, v2))
}

fn close(x: f64, y: f64, rel: f64) -> bool {
    x == y || (x.is_nan() && y.is_nan()) || (x - y).abs() <= rel * x.abs().max(y.abs())
}

fn same_value(a: &Value, b: &Value) -> bool {
    match (a, b) {
        (Value::F64(x), Value::F64(y)) => close(*x, *y, 1e-9),
        (Value::F32(x), Value::F32(y)) => close(f64::from(*x), f64::from(*y), 1e-6),
        (Value::List(x), Value::List(y)) => {
            x.len() == y.len() && x.iter().zip(y).all(|(p, q)| same_value(p, q))
        }
        (Value::Message(x), Value::Message(y)) => same_message(x, y),
        _ => a == b,
    }
}

/// Collects failures and reports the first few precisely.
#[derive(Default)]
pub struct Failures {
    /// Description of each failure.
    pub list: Vec<String>,
    /// How many checks were made.
    pub checked: usize,
}

impl Failures {
    /// Records one check; `failure` is `Some` when it failed.
    pub fn check(&mut self, failure: Option<String>) {
        self.checked += 1;
        if let Some(f) = failure {
            self.list.push(f);
        }
    }

    /// Panics listing the first failures if there is any.
    pub fn assert_none(&self, what: &str) {
        assert!(self.checked > 0, "{what}: nothing was checked");
        if !self.list.is_empty() {
            let shown: Vec<&str> = self.list.iter().take(8).map(String::as_str).collect();
            panic!(
                "{what}: {} of {} vectors fail; first ones:\n{}",
                self.list.len(),
                self.checked,
                shown.join("\n")
            );
        }
    }
}

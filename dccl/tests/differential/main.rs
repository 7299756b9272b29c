//! Differential test against the reference C++ library, libdccl 4.2.
//!
//! Random instances of every message of a set of `.proto` files are encoded
//! and decoded by this crate and by libdccl, and everything observable is
//! compared: whether a type loads, its definition hash, minimum and maximum
//! size and size report (`analyze`); for each instance whether it encodes, the
//! bytes (without and with a passphrase, and in strict mode), `size()`, the
//! decoded message (one-line text form), and how a damaged copy of the bytes
//! (cut, one bit flipped, one byte added) decodes.
//!
//! # Pointing it at a libdccl build
//!
//! The reference side is a small program ("driver") linked against libdccl
//! 4.2, built outside this repository. It takes `-f FILE.proto`
//! (repeatable), `-I DIR` (repeatable) and `-p PASSPHRASE`, prints `ready`,
//! then answers one line per command read on stdin (fields separated by
//! tabs):
//!
//! - `L NAME` loads a type: `ok HASH MIN_BYTES MAX_BYTES` (hash as libdccl's
//!   `hash_as_string`, sizes from `Codec::min_size` / `max_size`) or `err REASON`;
//! - `M NAME` selects the type for `E`: `ok`;
//! - `E TEXT` parses one text-format message (partial messages allowed) and
//!   encodes it: `ok HEX SIZE DECODED HEX_WITH_PASSPHRASE DECODED_WITH_PASSPHRASE
//!   HEX_STRICT` (`DECODED` is `ShortDebugString()` of the decoded message; a
//!   value starting with `!` is that codec's error), `err REASON` when encoding
//!   fails, `perr REASON` when the text does not parse;
//! - `D HEX` decodes bytes (no passphrase): `ok TYPE DECODED BYTES_USED` or `err REASON`;
//! - `A NAME` gives the size report (`Codec::info`): `ok TEXT` with each line
//!   break written as the byte 0x1f.
//!
//! To build one: build libdccl 4.2 from its source (tag `4.2.0`) with
//! cryptography enabled (Crypto++), then compile a C++ program doing the
//! above with `dccl::DynamicProtobufManager` (`enable_compilation`,
//! `add_include_path`, `load_from_proto_file`), three `dccl::Codec`s (plain,
//! with `set_crypto_passphrase`, with `set_strict(true)`),
//! `google::protobuf::TextFormat::Parser` with `AllowPartialMessage(true)` and
//! `Message::ShortDebugString()`. libdccl 4.2 sometimes throws a bare
//! `const google::protobuf::Descriptor*` when refusing a definition: catch it
//! (and anything else) and answer `err`. Files are passed to `-f` by their
//! name relative to the first `-I` directory holding them, as imports name them.
//!
//! # Running
//!
//! ```text
//! DCCL_REFERENCE_DRIVER=/path/to/driver cargo test -p dccl --test differential -- --nocapture
//! ```
//!
//! Without `DCCL_REFERENCE_DRIVER` the test prints that it is skipped and
//! passes. Other variables:
//!
//! - `DCCL_DIFF_PROTOS`: `:`-separated `.proto` files or directories
//!   (searched recursively for files using `dccl.msg`); default: this
//!   repository's example messages and the committed reference cases;
//! - `DCCL_DIFF_INCLUDE`: `:`-separated import directories;
//! - `DCCL_DIFF_INSTANCES` (default 40), `DCCL_DIFF_SEED` (default 1);
//! - `DCCL_DIFF_REPORT`: a file to write every difference to;
//! - `DCCL_DIFF_ACCEPT`: `,`-separated classes of difference (as printed,
//!   e.g. `min_size,max_size`) that are reported without failing the test;
//! - `DCCL_DIFF_TYPES`: `,`-separated full type names to compare (others skipped);
//! - `DCCL_DIFF_TEXT`: one text-format instance used instead of random ones;
//! - `DCCL_DIFF_NO_NAN`: when set, no NaN or infinity is generated;
//! - `DCCL_DIFF_RANDOM_DEFS=N`: also compare N random definitions (written to
//!   a temporary directory, kept there with `DCCL_DIFF_KEEP`; fields in number
//!   order only with `DCCL_DIFF_ORDERED`).
//!
//! The test fails when any difference is found and prints them by class.

mod definitions;
mod generator;

use std::collections::BTreeMap;
use std::io::{BufRead, BufReader, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, ChildStdin, ChildStdout, Command, Stdio};

use dccl::prost_reflect::{DynamicMessage, MessageDescriptor};
use dccl::Codec;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

const PASSPHRASE: &str = "differential";

/// One running reference driver.
struct Reference {
    child: Child,
    stdin: ChildStdin,
    stdout: BufReader<ChildStdout>,
}

impl Reference {
    fn start(driver: &Path, file: &Path, includes: &[PathBuf]) -> Result<Self, String> {
        // The file by its name relative to the first import directory holding
        // it, as an `import` names it (and as this crate's compiler names it).
        let virtual_name = includes
            .iter()
            .find_map(|dir| {
                let dir = std::fs::canonicalize(dir).ok()?;
                file.strip_prefix(dir).ok().map(Path::to_path_buf)
            })
            .unwrap_or_else(|| file.to_path_buf());
        let mut cmd = Command::new(driver);
        cmd.arg("-f").arg(virtual_name).arg("-p").arg(PASSPHRASE);
        for dir in includes {
            cmd.arg("-I").arg(dir);
        }
        let mut child = cmd
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .map_err(|e| format!("cannot start {}: {e}", driver.display()))?;
        let stdin = child.stdin.take().expect("piped stdin");
        let stdout = BufReader::new(child.stdout.take().expect("piped stdout"));
        let mut reference = Reference {
            child,
            stdin,
            stdout,
        };
        let first = reference.read_line()?;
        if first != "ready" {
            return Err(format!("reference cannot read {}: {first}", file.display()));
        }
        Ok(reference)
    }

    fn read_line(&mut self) -> Result<String, String> {
        let mut line = String::new();
        match self.stdout.read_line(&mut line) {
            Ok(0) => Err("reference driver exited".into()),
            Ok(_) => Ok(line.trim_end_matches(['\n', '\r']).to_string()),
            Err(e) => Err(format!("reading from reference driver: {e}")),
        }
    }

    /// Sends one command line; returns the reply split at tabs.
    fn ask(&mut self, command: &str) -> Result<Vec<String>, String> {
        writeln!(self.stdin, "{command}").map_err(|e| format!("writing to driver: {e}"))?;
        self.stdin.flush().map_err(|e| e.to_string())?;
        Ok(self.read_line()?.split('\t').map(str::to_string).collect())
    }
}

impl Drop for Reference {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Records one difference: `(list, type name, class, detail)`.
type RecordFn<'a> = &'a dyn Fn(&mut Vec<Difference>, &str, &'static str, String);

/// One observed difference.
#[derive(Debug)]
struct Difference {
    file: String,
    message: String,
    class: &'static str,
    detail: String,
}

fn env_paths(name: &str) -> Vec<PathBuf> {
    std::env::var(name)
        .ok()
        .map(|v| {
            v.split(':')
                .filter(|s| !s.is_empty())
                .map(PathBuf::from)
                .collect()
        })
        .unwrap_or_default()
}

fn collect_protos(path: &Path, out: &mut Vec<PathBuf>) {
    if path.is_dir() {
        let mut entries: Vec<_> = std::fs::read_dir(path)
            .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path()).collect())
            .unwrap_or_default();
        entries.sort();
        for entry in entries {
            collect_protos(&entry, out);
        }
    } else if path.extension().is_some_and(|e| e == "proto") {
        let text = std::fs::read_to_string(path).unwrap_or_default();
        if text.contains("dccl.msg") {
            out.push(path.to_path_buf());
        }
    }
}

fn default_protos() -> Vec<PathBuf> {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    vec![
        root.join("../protos/proto/goby/example"),
        root.join("tests/data/reference-cases"),
    ]
}

/// Types compared in a file: its top-level messages and nested messages
/// with `(dccl.msg)` options, in declaration order.
fn types_of(pool: &dccl::prost_reflect::DescriptorPool, file: &Path) -> Vec<MessageDescriptor> {
    let name = file.file_name().and_then(|n| n.to_str()).unwrap_or("");
    let mut out = Vec::new();
    for fd in pool.files() {
        let fname = fd.name().to_string();
        if !(fname == name || fname.ends_with(&format!("/{name}"))) {
            continue;
        }
        if !std::fs::canonicalize(file)
            .map(|p| p.to_string_lossy().ends_with(&fname))
            .unwrap_or(false)
        {
            continue;
        }
        fn walk(m: MessageDescriptor, top: bool, out: &mut Vec<MessageDescriptor>) {
            if top || dccl::field::has_message_options(&m) {
                out.push(m.clone());
            }
            for child in m.child_messages() {
                walk(child, false, out);
            }
        }
        for m in fd.messages() {
            walk(m, true, &mut out);
        }
        break;
    }
    out
}

struct Ours {
    plain: Codec,
    crypt: Codec,
    strict: Codec,
}

fn outcome<T, E: std::fmt::Display>(r: Result<T, E>) -> Result<T, String> {
    r.map_err(|e| e.to_string())
}

#[allow(clippy::too_many_arguments)]
fn compare_file(
    driver: &Path,
    file: &Path,
    includes: &[PathBuf],
    instances: usize,
    seed: u64,
    diffs: &mut Vec<Difference>,
    counts: &mut BTreeMap<&'static str, usize>,
) {
    let fname = file.display().to_string();
    let push = |diffs: &mut Vec<Difference>, message: &str, class: &'static str, detail: String| {
        diffs.push(Difference {
            file: fname.clone(),
            message: message.to_string(),
            class,
            detail,
        })
    };
    let pool = dccl::compile_protos(&[file], includes);
    let reference = Reference::start(driver, file, includes);
    let (pool, mut reference) = match (pool, reference) {
        (Ok(p), Ok(r)) => (p, r),
        (Err(e), Ok(_)) => {
            push(
                diffs,
                "",
                "file-acceptance",
                format!("ours: {e}; reference reads it"),
            );
            return;
        }
        (Ok(_), Err(e)) => {
            push(
                diffs,
                "",
                "file-acceptance",
                format!("ours reads it; reference: {e}"),
            );
            return;
        }
        (Err(e), Err(_)) => {
            *counts.entry("files unreadable by both").or_default() += 1;
            eprintln!("both cannot read {fname}: {e}");
            return;
        }
    };
    *counts.entry("files").or_default() += 1;
    let mut ours = Ours {
        plain: Codec::new(),
        crypt: Codec::new(),
        strict: Codec::new(),
    };
    ours.crypt.set_passphrase(PASSPHRASE);
    ours.strict.set_strict(true);
    let now = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map(|d| d.as_secs_f64())
        .unwrap_or(0.0);
    let only: Vec<String> = std::env::var("DCCL_DIFF_TYPES")
        .map(|v| v.split(',').map(str::to_string).collect())
        .unwrap_or_default();
    let fixed_text = std::env::var("DCCL_DIFF_TEXT").ok();
    for desc in types_of(&pool, file) {
        let name = desc.full_name().to_string();
        if !only.is_empty() && !only.contains(&name) {
            continue;
        }
        *counts.entry("types").or_default() += 1;
        let Ok(reply) = reference.ask(&format!("L {name}")) else {
            push(diffs, &name, "reference-crash", "on load".into());
            return;
        };
        let our_load = ours
            .plain
            .load(&desc)
            .and_then(|_| ours.crypt.load(&desc))
            .and_then(|_| ours.strict.load(&desc));
        match (reply[0].as_str(), &our_load) {
            ("ok", Ok(())) => {
                *counts.entry("types loaded").or_default() += 1;
                let hash = ours
                    .plain
                    .hash(&name)
                    .map(|h| format!("{h:#018x}"))
                    .unwrap_or_default();
                if hash != reply[1] {
                    push(
                        diffs,
                        &name,
                        "hash",
                        format!("ours {hash} reference {}", reply[1]),
                    );
                }
                let min = ours.plain.min_size(&name).map(|s| s.to_string());
                if min.as_deref().unwrap_or("?") != reply[2] {
                    push(
                        diffs,
                        &name,
                        "min_size",
                        format!("ours {min:?} reference {}", reply[2]),
                    );
                }
                // The size report, line by line.
                if let Ok(reply) = reference.ask(&format!("A {name}")) {
                    let theirs = reply
                        .get(1)
                        .cloned()
                        .unwrap_or_default()
                        .replace('\u{1f}', "\n");
                    let ours_text = ours
                        .plain
                        .analyze(&name)
                        .unwrap_or_else(|e| format!("!{e}"));
                    let differing: Vec<String> = theirs
                        .lines()
                        .zip(ours_text.lines())
                        .filter(|(a, b)| a.trim_end() != b.trim_end())
                        .map(|(a, b)| format!("\n      ref  {a}\n      ours {b}"))
                        .collect();
                    if !differing.is_empty() || theirs.lines().count() != ours_text.lines().count()
                    {
                        push(diffs, &name, "analyze", differing.concat());
                    }
                }
                let max = ours.plain.max_size(&name).map(|s| s.to_string());
                if max.as_deref().unwrap_or("?") != reply[3] {
                    push(
                        diffs,
                        &name,
                        "max_size",
                        format!("ours {max:?} reference {}", reply[3]),
                    );
                }
            }
            ("ok", Err(e)) => {
                push(
                    diffs,
                    &name,
                    "load-acceptance",
                    format!("ours refuses: {e}"),
                );
                continue;
            }
            (_, Ok(())) => {
                push(
                    diffs,
                    &name,
                    "load-acceptance",
                    format!(
                        "reference refuses: {}",
                        reply.get(1).cloned().unwrap_or_default()
                    ),
                );
                ours.plain.unload(&name);
                ours.crypt.unload(&name);
                ours.strict.unload(&name);
                continue;
            }
            (_, Err(_)) => {
                *counts.entry("types refused by both").or_default() += 1;
                continue;
            }
        }
        if reference.ask(&format!("M {name}")).map(|r| r[0] == "ok") != Ok(true) {
            push(diffs, &name, "reference-crash", "on select".into());
            return;
        }
        let mut rng = ChaCha8Rng::seed_from_u64(seed ^ name_hash(name.as_bytes()));
        for _ in 0..if fixed_text.is_some() { 1 } else { instances } {
            let text = match &fixed_text {
                Some(t) => t.clone(),
                None => {
                    let mut generator = generator::Generator::new(&mut rng, now);
                    generator.non_finite = std::env::var_os("DCCL_DIFF_NO_NAN").is_none();
                    generator.instance(&desc)
                }
            };
            *counts.entry("instances").or_default() += 1;
            let Ok(reply) = reference.ask(&format!("E {text}")) else {
                push(diffs, &name, "reference-crash", format!("on input {text}"));
                return;
            };
            let msg = DynamicMessage::parse_text_format(desc.clone(), &text);
            let msg = match (reply[0].as_str(), msg) {
                ("perr", Err(_)) => continue,
                ("perr", Ok(_)) => {
                    push(
                        diffs,
                        &name,
                        "text-parse",
                        format!("reference cannot parse {text}: {}", reply[1]),
                    );
                    continue;
                }
                (_, Err(e)) => {
                    push(
                        diffs,
                        &name,
                        "text-parse",
                        format!("we cannot parse {text}: {e}"),
                    );
                    continue;
                }
                (_, Ok(m)) => m,
            };
            let encoded = outcome(ours.plain.encode(&msg));
            match (reply[0].as_str(), &encoded) {
                ("ok", Ok(bytes)) => {
                    *counts.entry("instances encoded by both").or_default() += 1;
                    let hex = hex::encode(bytes);
                    if hex != reply[1] {
                        // How does the reference read our bytes?
                        let theirs = reference
                            .ask(&format!("D {hex}"))
                            .map(|r| r.join(" "))
                            .unwrap_or_default();
                        push(
                            diffs,
                            &name,
                            "encoding",
                            format!("input {text}\n      ours {hex}\n      ref  {}\n      ref reads ours as: {theirs}\n      ref decoded: {}", reply[1], reply[3]),
                        );
                    }
                    // Damaged bytes (cut, a bit flipped, a byte added) decode
                    // (or fail) alike.
                    if hex == reply[1] && !bytes.is_empty() {
                        let mut damaged = bytes.clone();
                        match rng.random_range(0..3) {
                            0 => {
                                damaged.truncate(rng.random_range(0..bytes.len()));
                            }
                            1 => {
                                let bit = rng.random_range(0..bytes.len() * 8);
                                damaged[bit / 8] ^= 0x80 >> (bit % 8);
                            }
                            _ => damaged.push(rng.random()),
                        }
                        compare_decode(&mut reference, &ours.plain, &damaged, &name, diffs, &push);
                    }
                    // Strict mode: the same values refused, the others coded alike.
                    let strict = ours.strict.encode(&msg).map(hex::encode);
                    let theirs_strict = reply.get(6).cloned().unwrap_or_default();
                    match (&strict, theirs_strict.strip_prefix('!')) {
                        (Ok(ours_hex), None) if *ours_hex != theirs_strict && hex == reply[1] => push(
                            diffs,
                            &name,
                            "strict-encoding",
                            format!("input {text}\n      ours {ours_hex}\n      ref  {theirs_strict}"),
                        ),
                        (Ok(ours_hex), Some(reason)) => push(
                            diffs,
                            &name,
                            "strict-acceptance",
                            format!("input {text}\n      ours {ours_hex}\n      ref refuses: {reason}"),
                        ),
                        (Err(e), None) => push(
                            diffs,
                            &name,
                            "strict-acceptance",
                            format!("input {text}\n      ours refuses: {e}\n      ref  {theirs_strict}"),
                        ),
                        _ => {}
                    }
                    let size = outcome(ours.plain.size(&msg)).map(|s| s.to_string());
                    if size.as_deref().unwrap_or("?") != reply[2] {
                        push(
                            diffs,
                            &name,
                            "size",
                            format!("input {text}: ours {size:?} reference {}", reply[2]),
                        );
                    }
                    let decoded = match ours.plain.decode(bytes) {
                        Ok(m) => dccl::short_debug_string(&m),
                        Err(e) => format!("!{e}"),
                    };
                    if decoded != reply[3] && hex == reply[1] {
                        push(
                            diffs,
                            &name,
                            "decoded",
                            format!(
                                "input {text}\n      ours {decoded}\n      ref  {}",
                                reply[3]
                            ),
                        );
                    }
                    let crypt = outcome(ours.crypt.encode(&msg));
                    match &crypt {
                        Ok(b) => {
                            let chex = hex::encode(b);
                            if chex != reply[4] && hex == reply[1] {
                                push(
                                    diffs,
                                    &name,
                                    "encoding-with-passphrase",
                                    format!(
                                        "input {text}\n      ours {chex}\n      ref  {}",
                                        reply[4]
                                    ),
                                );
                            }
                            let cdec = match ours.crypt.decode(b) {
                                Ok(m) => dccl::short_debug_string(&m),
                                Err(e) => format!("!{e}"),
                            };
                            if cdec != reply[5] && chex == reply[4] && decoded == reply[3] {
                                push(
                                    diffs,
                                    &name,
                                    "decoded-with-passphrase",
                                    format!(
                                        "input {text}\n      ours {cdec}\n      ref  {}",
                                        reply[5]
                                    ),
                                );
                            }
                        }
                        Err(e) => push(
                            diffs,
                            &name,
                            "encoding-with-passphrase",
                            format!("input {text}: ours fails: {e}"),
                        ),
                    }
                }
                ("ok", Err(e)) => push(
                    diffs,
                    &name,
                    "encode-acceptance",
                    format!(
                        "input {text}\n      ours refuses: {e}\n      ref  {}",
                        reply[1]
                    ),
                ),
                (_, Ok(bytes)) => push(
                    diffs,
                    &name,
                    "encode-acceptance",
                    format!(
                        "input {text}\n      reference refuses: {}\n      ours {}",
                        reply.get(1).cloned().unwrap_or_default(),
                        hex::encode(bytes)
                    ),
                ),
                (_, Err(_)) => {
                    *counts.entry("instances refused by both").or_default() += 1;
                }
            }
        }
    }
}

/// Decodes `bytes` on both sides and records a difference in acceptance,
/// decoded message or bytes used.
fn compare_decode(
    reference: &mut Reference,
    ours: &Codec,
    bytes: &[u8],
    name: &str,
    diffs: &mut Vec<Difference>,
    push: RecordFn<'_>,
) {
    let hex = hex::encode(bytes);
    let Ok(theirs) = reference.ask(&format!("D {hex}")) else {
        push(diffs, name, "reference-crash", format!("on decoding {hex}"));
        return;
    };
    let ours = ours
        .decode_with(bytes, &dccl::DecodeOptions::default())
        .map(|d| (dccl::short_debug_string(&d.message), d.len));
    match (theirs[0].as_str(), ours) {
        ("ok", Ok((text, used))) => {
            if text != theirs[2] || used.to_string() != theirs[3] {
                push(
                    diffs,
                    name,
                    "decode-damaged",
                    format!(
                        "bytes {hex}\n      ours {text} ({used} bytes)\n      ref  {} ({} bytes)",
                        theirs[2], theirs[3]
                    ),
                );
            }
        }
        ("ok", Err(e)) => push(
            diffs,
            name,
            "decode-damaged-acceptance",
            format!(
                "bytes {hex}\n      ours refuses: {e}\n      ref  {}",
                theirs[2]
            ),
        ),
        (_, Ok((text, _))) => push(
            diffs,
            name,
            "decode-damaged-acceptance",
            format!(
                "bytes {hex}\n      ours {text}\n      ref refuses: {}",
                theirs.get(1).cloned().unwrap_or_default()
            ),
        ),
        (_, Err(_)) => {}
    }
}

#[test]
#[ignore = "needs DCCL_REFERENCE_DRIVER, a libdccl 4.2 reference driver: cargo test -p dccl --test differential -- --ignored"]
fn differential_against_libdccl_when_a_reference_driver_is_given() {
    let Some(driver) = std::env::var_os("DCCL_REFERENCE_DRIVER").map(PathBuf::from) else {
        panic!(
            "set DCCL_REFERENCE_DRIVER=path to a libdccl 4.2 reference driver \
             (see the doc comment of dccl/tests/differential/main.rs)"
        );
    };
    let mut roots = env_paths("DCCL_DIFF_PROTOS");
    if roots.is_empty() {
        roots = default_protos();
    }
    let includes = env_paths("DCCL_DIFF_INCLUDE");
    let instances = std::env::var("DCCL_DIFF_INSTANCES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(40);
    let seed = std::env::var("DCCL_DIFF_SEED")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(1);
    let mut files = Vec::new();
    for root in &roots {
        collect_protos(
            &std::fs::canonicalize(root).unwrap_or(root.clone()),
            &mut files,
        );
    }
    let mut diffs = Vec::new();
    let mut counts = BTreeMap::new();
    for file in &files {
        compare_file(
            &driver,
            file,
            &includes,
            instances,
            seed,
            &mut diffs,
            &mut counts,
        );
    }
    // Random definitions, written to a temporary directory.
    let random_defs: usize = std::env::var("DCCL_DIFF_RANDOM_DEFS")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(0);
    if random_defs > 0 {
        let dir =
            std::env::temp_dir().join(format!("dccl-differential-{}-{seed}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temporary directory");
        let dir = std::fs::canonicalize(&dir).expect("temporary directory");
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let opts = definitions::DefinitionOptions {
            ordered: std::env::var_os("DCCL_DIFF_ORDERED").is_some(),
        };
        for i in 0..random_defs {
            let text = definitions::definition(&mut rng, 1 + (i as u32 % 500), &opts);
            let file = dir.join(format!("def{i}.proto"));
            std::fs::write(&file, text).expect("write definition");
            compare_file(
                &driver,
                &file,
                std::slice::from_ref(&dir),
                instances,
                seed,
                &mut diffs,
                &mut counts,
            );
        }
        if std::env::var_os("DCCL_DIFF_KEEP").is_none() {
            let _ = std::fs::remove_dir_all(&dir);
        } else {
            println!("random definitions kept in {}", dir.display());
        }
    }
    let mut by_class: BTreeMap<&str, Vec<&Difference>> = BTreeMap::new();
    for d in &diffs {
        by_class.entry(d.class).or_default().push(d);
    }
    println!("compared: {counts:?}");
    let mut report = String::new();
    for (class, list) in &by_class {
        let mut types: Vec<&str> = list.iter().map(|d| d.message.as_str()).collect();
        types.dedup();
        report.push_str(&format!(
            "== {class}: {} differences in {} types\n",
            list.len(),
            types.len()
        ));
        for d in list {
            report.push_str(&format!("  [{}] {}: {}\n", d.file, d.message, d.detail));
        }
    }
    if let Ok(path) = std::env::var("DCCL_DIFF_REPORT") {
        std::fs::write(&path, &report).expect("write report");
    }
    for (class, list) in &by_class {
        println!("{class}: {} differences", list.len());
        for d in list.iter().take(3) {
            println!("  {}: {}", d.message, d.detail);
        }
    }
    // Classes listed in DCCL_DIFF_ACCEPT are reported but do not fail the test.
    let accepted: Vec<String> = std::env::var("DCCL_DIFF_ACCEPT")
        .map(|v| v.split(',').map(|c| c.trim().to_string()).collect())
        .unwrap_or_default();
    let failing = diffs
        .iter()
        .filter(|d| !accepted.iter().any(|c| c == d.class))
        .count();
    assert!(
        failing == 0,
        "{failing} differences with libdccl (classes not in DCCL_DIFF_ACCEPT)"
    );
}

/// `std::hash<std::string>` of the GNU C++ library on 64-bit targets (a
/// MurmurHash2 variant), the hash the instance seeds have always been mixed
/// with, so that a `DCCL_DIFF_SEED` keeps giving the same instances.
fn name_hash(bytes: &[u8]) -> u64 {
    const MUL: u64 = 0xc6a4_a793_5bd1_e995;
    let shift_mix = |v: u64| v ^ (v >> 47);
    let mut hash = 0xc70f_6907 ^ (bytes.len() as u64).wrapping_mul(MUL);
    let mut chunks = bytes.chunks_exact(8);
    for chunk in &mut chunks {
        let word = u64::from_le_bytes(chunk.try_into().expect("8 bytes"));
        hash ^= shift_mix(word.wrapping_mul(MUL)).wrapping_mul(MUL);
        hash = hash.wrapping_mul(MUL);
    }
    let rest = chunks.remainder();
    if !rest.is_empty() {
        let data = rest
            .iter()
            .rev()
            .fold(0u64, |acc, &b| (acc << 8).wrapping_add(b as u64));
        hash ^= data;
        hash = hash.wrapping_mul(MUL);
    }
    shift_mix(shift_mix(hash).wrapping_mul(MUL))
}

#[test]
fn name_hash_is_the_gnu_string_hash() {
    assert_eq!(name_hash(b""), 0x553e_9390_1e46_2a6e);
}

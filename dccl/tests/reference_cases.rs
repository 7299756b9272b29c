//! Small definitions, each showing one kind of difference the differential
//! test (`tests/differential`) found against libdccl 4.2, with libdccl's own
//! outputs for them. Each folder of `tests/data/reference-cases/` holds:
//!
//! - `case.proto`: the definitions;
//! - `input.txt`: one message per line, `|full.TypeName| text format`;
//! - `expected.hex`: libdccl's encoding of each line (`error: …` when it refuses);
//! - `expected-passphrase.hex`: the same with the passphrase `differential`;
//! - `expected-decoded.txt`: libdccl's `ShortDebugString()` of each decoded line;
//! - `expected-size.txt`: libdccl's `Codec::size()` of each line;
//! - `expected-hash.txt`: `TypeName HASH MIN_SIZE MAX_SIZE` from libdccl's
//!   `Codec::load`, `min_size` and `max_size`;
//! - `expected-analyze.txt`: libdccl's size report (`Codec::info`) of each
//!   type, in the order the types first appear in `input.txt`.
//!
//! Where this crate deliberately or for now behaves otherwise the test says
//! so in its `#[ignore]` reason.

use std::path::{Path, PathBuf};

use dccl::prost_reflect::DynamicMessage;
use dccl::Codec;

const PASSPHRASE: &str = "differential";

fn case_dir(name: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data/reference-cases")
        .join(name)
}

fn lines(dir: &Path, file: &str) -> Vec<String> {
    std::fs::read_to_string(dir.join(file))
        .unwrap_or_else(|e| panic!("{}: {e}", dir.join(file).display()))
        .lines()
        .map(str::to_string)
        .collect()
}

/// One case loaded into a plain codec and a codec with the passphrase.
struct Case {
    dir: PathBuf,
    plain: Codec,
    crypt: Codec,
    /// `(type name, text)` of each input line.
    inputs: Vec<(String, String)>,
    /// Types libdccl refuses to load (`error:` in `expected-hash.txt`).
    refused: Vec<String>,
    pool: dccl::prost_reflect::DescriptorPool,
}

impl Case {
    fn open(name: &str) -> Case {
        let dir = case_dir(name);
        let pool = dccl::compile_protos(&[dir.join("case.proto")], &[&dir])
            .unwrap_or_else(|e| panic!("{name}: {e}"));
        let inputs: Vec<(String, String)> = lines(&dir, "input.txt")
            .into_iter()
            .filter(|l| !l.trim().is_empty())
            .map(|l| {
                let rest = l.strip_prefix('|').expect("line starts with |Type|");
                let (ty, text) = rest.split_once('|').expect("closing |");
                (ty.to_string(), text.trim().to_string())
            })
            .collect();
        let refused: Vec<String> = lines(&dir, "expected-hash.txt")
            .iter()
            .filter_map(|l| l.split_once(' '))
            .filter(|(_, rest)| rest.starts_with("error"))
            .map(|(ty, _)| ty.to_string())
            .collect();
        let mut plain = Codec::new();
        let mut crypt = Codec::new();
        crypt.set_passphrase(PASSPHRASE);
        for (ty, _) in &inputs {
            if plain.descriptor(ty).is_none() && !refused.contains(ty) {
                let desc = pool.get_message_by_name(ty).expect("type in case.proto");
                plain.load(&desc).unwrap_or_else(|e| panic!("{ty}: {e}"));
                crypt.load(&desc).unwrap_or_else(|e| panic!("{ty}: {e}"));
            }
        }
        Case {
            dir,
            plain,
            crypt,
            inputs,
            refused,
            pool,
        }
    }

    fn message(&self, i: usize) -> DynamicMessage {
        let (ty, text) = &self.inputs[i];
        let desc = self.pool.get_message_by_name(ty).expect("type");
        DynamicMessage::parse_text_format(desc, text).unwrap_or_else(|e| panic!("{text}: {e}"))
    }

    /// Encodings with and without the passphrase are libdccl's.
    fn check_encoding(&self) {
        let expected = lines(&self.dir, "expected.hex");
        let expected_crypt = lines(&self.dir, "expected-passphrase.hex");
        for i in 0..self.inputs.len() {
            let msg = self.message(i);
            let ours = self.plain.encode(&msg).map(hex::encode);
            let ours_crypt = self.crypt.encode(&msg).map(hex::encode);
            if expected[i].starts_with("error") {
                assert!(ours.is_err(), "line {}: libdccl refuses, we encode", i + 1);
                continue;
            }
            assert_eq!(
                ours.as_deref().ok(),
                Some(expected[i].as_str()),
                "line {} ({})",
                i + 1,
                self.inputs[i].1
            );
            assert_eq!(
                ours_crypt.as_deref().ok(),
                Some(expected_crypt[i].as_str()),
                "line {} with passphrase",
                i + 1
            );
        }
    }

    /// Decoding libdccl's bytes gives libdccl's decoded message.
    fn check_decoding(&self) {
        let expected = lines(&self.dir, "expected.hex");
        let decoded = lines(&self.dir, "expected-decoded.txt");
        for i in 0..self.inputs.len() {
            if expected[i].starts_with("error") {
                continue;
            }
            let bytes = hex::decode(&expected[i]).expect("hex");
            let back = self
                .plain
                .decode(&bytes)
                .unwrap_or_else(|e| panic!("line {}: {e}", i + 1));
            assert_eq!(
                dccl::short_debug_string(&back),
                decoded[i],
                "line {}",
                i + 1
            );
        }
    }

    /// Definition hashes are libdccl's; the types it refuses are refused.
    fn check_hashes(&self) {
        for line in lines(&self.dir, "expected-hash.txt") {
            let parts: Vec<&str> = line.split_whitespace().collect();
            if self.refused.iter().any(|t| t == parts[0]) {
                let desc = self.pool.get_message_by_name(parts[0]).expect("type");
                let result = Codec::new().load(&desc);
                assert!(
                    result.is_err(),
                    "{}: libdccl refuses it, it loads here",
                    parts[0]
                );
                continue;
            }
            let ours = self.plain.hash(parts[0]).expect("loaded");
            assert_eq!(format!("{ours:#018x}"), parts[1], "{}", parts[0]);
        }
    }

    /// `size()` is libdccl's `Codec::size()`.
    fn check_size(&self) {
        let expected = lines(&self.dir, "expected-size.txt");
        assert_eq!(expected.len(), self.inputs.len());
        for (i, want) in expected.iter().enumerate() {
            if want == "error" {
                continue;
            }
            let ours = self.plain.size(&self.message(i)).expect("size");
            assert_eq!(
                &ours.to_string(),
                want,
                "line {} ({})",
                i + 1,
                self.inputs[i].1
            );
        }
    }

    /// `size()` is the length of the encoding.
    fn check_size_is_encoded_length(&self) {
        let expected = lines(&self.dir, "expected.hex");
        assert_eq!(expected.len(), self.inputs.len());
        for (i, want) in expected.iter().enumerate() {
            if want.starts_with("error") {
                continue;
            }
            let ours = self.plain.size(&self.message(i)).expect("size");
            assert_eq!(ours, want.len() / 2, "line {}", i + 1);
        }
    }

    /// The size report of each type is libdccl's.
    fn check_analyze(&self) {
        let expected = std::fs::read_to_string(self.dir.join("expected-analyze.txt"))
            .expect("expected-analyze.txt");
        let mut ours = String::new();
        let mut seen: Vec<&str> = Vec::new();
        for (ty, _) in &self.inputs {
            if !seen.contains(&ty.as_str()) && !self.refused.contains(ty) {
                seen.push(ty);
                ours.push_str(&self.plain.analyze(ty).expect("analyze"));
            }
        }
        assert_eq!(ours, expected);
    }

    /// `min_size` / `max_size` of each type are libdccl's.
    fn check_min_max(&self) {
        for line in lines(&self.dir, "expected-hash.txt") {
            let parts: Vec<&str> = line.split_whitespace().collect();
            let min = self.plain.min_size(parts[0]).expect("loaded");
            let max = self.plain.max_size(parts[0]).expect("loaded");
            assert_eq!(
                (min.to_string(), max.to_string()),
                (parts[2].to_string(), parts[3].to_string()),
                "{}",
                parts[0]
            );
        }
    }
}

/// Every folder has a test below.
#[test]
fn every_reference_case_is_tested() {
    let tested = [
        "v2-codec-named-in-newer-message",
        "utf8-cut-at-max-length",
        "size-under-min-repeat",
        "size-bounds-and-id-width",
        "v2-repeated-embedded-message-hash",
        "v2-repeated-embedded-message-in-head",
        "analyze-oneof-sizes",
        "v2-embedded-message-in-head-hash",
        "oneof-in-v2-message-refused",
        "v3-message-codec-in-v2-message",
        "oneof-inside-head-message",
    ];
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/reference-cases");
    for entry in std::fs::read_dir(dir).expect("reference-cases") {
        let entry = entry.expect("entry");
        if !entry.path().is_dir() {
            continue;
        }
        let name = entry.file_name().to_string_lossy().to_string();
        assert!(
            tested.contains(&name.as_str()),
            "no test for reference case {name}"
        );
    }
}

// `codec: "dccl.default2"` on a string keeps the 8-bit length prefix of
// version 2 and on an enum packs it (ignoring `packed_enum: false`), in a
// message of any codec_version; `dccl.default3` likewise keeps version 3's.
#[test]
fn v2_codec_named_in_newer_message() {
    let case = Case::open("v2-codec-named-in-newer-message");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size();
}

// A string cut at max_length inside a multi-byte character: the bytes on the
// wire are libdccl's.
#[test]
fn utf8_cut_at_max_length_encoding() {
    let case = Case::open("utf8-cut-at-max-length");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_size();
}

// libdccl decodes the cut string to bytes that are not valid UTF-8; a protobuf
// `string` here must be valid UTF-8, so the partial character is read as U+FFFD.
#[test]
#[ignore = "known difference: libdccl decodes a string cut inside a UTF-8 character to invalid UTF-8 (the partial bytes); a Rust string cannot hold them, the partial character becomes U+FFFD"]
fn utf8_cut_at_max_length_decoding() {
    Case::open("utf8-cut-at-max-length").check_decoding();
}

// Fewer elements than min_repeat: the wire carries min_repeat elements (the
// missing ones as zero) and decodes to them.
#[test]
fn size_under_min_repeat_encoding() {
    let case = Case::open("size-under-min-repeat");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size_is_encoded_length();
}

// libdccl's Codec::size() counts only the elements given, not the padding to
// min_repeat that encode() writes, so it is smaller than the encoding.
#[test]
#[ignore = "known difference: libdccl's Codec::size() leaves out the padding to min_repeat that its encode() writes; size() here is the encoded length"]
fn size_under_min_repeat_reference_size() {
    Case::open("size-under-min-repeat").check_size();
}

#[test]
fn size_bounds_and_id_width_encoding() {
    let case = Case::open("size-bounds-and-id-width");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size();
}

// libdccl's Codec::min_size / max_size count the id as the id codec's
// smallest / largest width (8 / 16 bits) whatever the type's id is; here they
// count the id as encoded (the sizes analyze and the load check use).
#[test]
#[ignore = "known difference: libdccl's Codec::min_size/max_size take the id as 8/16 bits for every type; min_size/max_size here use the type's own id width"]
fn size_bounds_and_id_width_min_max() {
    Case::open("size-bounds-and-id-width").check_min_max();
}

// Version 2 hashes a repeated embedded message (default message codec) in
// both parts, as it does a singular one.
#[test]
fn v2_repeated_embedded_message_hash() {
    let case = Case::open("v2-repeated-embedded-message-hash");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size();
}

#[test]
fn v2_repeated_embedded_message_in_head_hash() {
    Case::open("v2-repeated-embedded-message-in-head").check_hashes();
}

// Version 2 codes the head fields of every element of a repeated embedded
// message in the head (all max_repeat of them) and the other fields in the
// body, and decodes the head values and the body values as elements of their
// own, the body's after the head's.
#[test]
fn v2_repeated_embedded_message_in_head_coding() {
    let case = Case::open("v2-repeated-embedded-message-in-head");
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size();
}

// The size report writes a oneof's sizes as `min-max` even when they are equal.
#[test]
fn analyze_oneof_sizes() {
    let case = Case::open("analyze-oneof-sizes");
    case.check_hashes();
    case.check_encoding();
    case.check_decoding();
    case.check_analyze();
}

// Version 2 hashes an embedded message with `in_head` set in the other part
// too (with none of its fields there).
#[test]
fn v2_embedded_message_in_head_hash() {
    let case = Case::open("v2-embedded-message-in-head-hash");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size();
}

// A oneof in a message coded by the version 2 (or 3) message codec is refused
// at load, root or embedded; with the version 4 codec it is coded.
#[test]
fn oneof_in_v2_message_refused() {
    let case = Case::open("oneof-in-v2-message-refused");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size();
}

// The repeated framing of a field follows the root message's codec_version,
// also for an embedded message coded with a codec of another version.
#[test]
fn v3_message_codec_in_v2_message() {
    let case = Case::open("v3-message-codec-in-v2-message");
    case.check_hashes();
    case.check_analyze();
    case.check_encoding();
    case.check_decoding();
    case.check_size();
}

// libdccl accepts a oneof inside an embedded message placed in the head, but
// its decoding does not give back what it encoded (see expected-decoded.txt);
// here such a message is refused at load (its head size is not fixed).
#[test]
#[ignore = "known difference: a oneof inside an in_head embedded message: libdccl loads it and codes it without the oneof case (and does not decode its own bytes to the values given); here it is refused at load"]
fn oneof_inside_head_message() {
    let case = Case::open("oneof-inside-head-message");
    case.check_hashes();
    case.check_encoding();
}

//! The field cases: small definitions, each showing one pattern on which
//! message sets in use today met a difference with libdccl 4.2, with the
//! reference's outputs. Every case runs twice: on the copy committed in
//! `tests/data/field-cases/` (so a clone alone tests them) and on
//! `../shared/dccl-field-cases/` beside the project (skipped, with a
//! message, when that folder is absent). Expected values are read from the
//! files of each case.

use std::path::{Path, PathBuf};

use dccl::prost_reflect::{DescriptorPool, DynamicMessage, ReflectMessage};
use dccl::{Codec, Error};

/// A fixed clock for the time codec: 2023-11-14 22:13:20 UTC.
const NOW: i64 = 1_700_000_000;

/// The folders holding `case`: the committed copy, and the shared one when present.
fn case_dirs(case: &str) -> Vec<PathBuf> {
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let mut dirs = vec![root.join("tests/data/field-cases").join(case)];
    let shared = root.join("../../shared/dccl-field-cases").join(case);
    if shared.is_dir() {
        dirs.push(shared);
    } else {
        eprintln!(
            "SKIPPED: {} is absent; case {case} runs on the committed copy only",
            shared.display()
        );
    }
    dirs
}

fn read(dir: &Path, file: &str) -> String {
    std::fs::read_to_string(dir.join(file))
        .unwrap_or_else(|e| panic!("{}: {e}", dir.join(file).display()))
}

fn lines(text: &str) -> Vec<&str> {
    text.lines().filter(|l| !l.trim().is_empty()).collect()
}

/// Compiles `proto` of `dir` (no include path) and loads every valid DCCL
/// message of it.
fn load(dir: &Path, proto: &str) -> (Codec, DescriptorPool, dccl::FileLoad) {
    let pool = dccl::compile_protos(&[dir.join(proto)], &[] as &[PathBuf])
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    let mut codec = Codec::new();
    codec.set_clock(|| NOW);
    let report = codec
        .load_valid_messages(&pool, proto)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()));
    (codec, pool, report)
}

/// Encodes each line of `input` as `type_name` and compares with the line of
/// `expected`; decodes each expected line and checks that it encodes back to it.
fn check_encodings(
    dir: &Path,
    codec: &Codec,
    pool: &DescriptorPool,
    type_name: &str,
    input: &str,
    expected: &str,
) {
    let desc = pool.get_message_by_name(type_name).unwrap();
    let input = read(dir, input);
    let expected = read(dir, expected);
    let (input, expected) = (lines(&input), lines(&expected));
    assert_eq!(input.len(), expected.len(), "{}", dir.display());
    for (text, hex) in input.iter().zip(&expected) {
        let msg = DynamicMessage::parse_text_format(desc.clone(), text).unwrap();
        let bytes = codec
            .encode(&msg)
            .unwrap_or_else(|e| panic!("{}: {text}: {e}", dir.display()));
        assert_eq!(
            hex::encode(&bytes),
            *hex,
            "{}: encoding {text}",
            dir.display()
        );
        assert_eq!(
            codec.size(&msg).unwrap(),
            bytes.len(),
            "{}: size of {text}",
            dir.display()
        );
        let reference = hex::decode(hex).unwrap();
        let dccl::Decoded {
            message: back,
            len: used,
        } = codec
            .decode_with(&reference, &dccl::DecodeOptions::as_type(type_name))
            .unwrap_or_else(|e| panic!("{}: decoding {hex}: {e}", dir.display()));
        assert_eq!(used, reference.len(), "{}: {hex}", dir.display());
        assert_eq!(
            hex::encode(codec.encode(&back).unwrap()),
            *hex,
            "{}: {hex} decoded as {back} does not encode back",
            dir.display()
        );
    }
}

/// The one message type the case loads.
fn only_loaded(codec: &Codec, dir: &Path) -> String {
    let loaded = codec.loaded();
    assert_eq!(loaded.len(), 1, "{}: {loaded:?}", dir.display());
    loaded[0].clone()
}

#[test]
fn field_declaration_order() {
    for dir in case_dirs("field-declaration-order") {
        let (codec, pool, _) = load(&dir, "case.proto");
        let name = only_loaded(&codec, &dir);
        check_encodings(&dir, &codec, &pool, &name, "input.txt", "expected.hex");
    }
}

#[test]
fn nan_in_numeric_fields() {
    for dir in case_dirs("nan-in-numeric-fields") {
        let (codec, pool, _) = load(&dir, "case.proto");
        let name = only_loaded(&codec, &dir);
        check_encodings(&dir, &codec, &pool, &name, "input.txt", "expected.hex");
        let (codec, pool, _) = load(&dir, "variants.proto");
        for name in codec.loaded() {
            let short = name.rsplit('.').next().unwrap().to_lowercase();
            let input = format!("variants-{short}-input.txt");
            assert!(dir.join(&input).is_file(), "{}: no {input}", dir.display());
            let expected = format!("variants-{short}-expected.hex");
            check_encodings(&dir, &codec, &pool, &name, &input, &expected);
        }
    }
}

#[test]
fn file_with_non_dccl_helper_message() {
    for dir in case_dirs("file-with-non-dccl-helper-message") {
        let (codec, pool, report) = load(&dir, "case.proto");
        assert_eq!(report.loaded, vec!["fuzzcase.Status".to_string()]);
        let skipped: Vec<&str> = report.skipped.iter().map(|s| s.name.as_str()).collect();
        assert_eq!(skipped, vec!["fuzzcase.Helper"], "{}", dir.display());
        let why = report.skipped[0].error.to_string();
        assert!(why.contains("id"), "{why}");
        check_encodings(
            &dir,
            &codec,
            &pool,
            "fuzzcase.Status",
            "input.txt",
            "expected.hex",
        );
        // Decoding by id works with the whole file loaded.
        for hex in lines(&read(&dir, "expected.hex")) {
            let msg = codec.decode(&hex::decode(hex).unwrap()).unwrap();
            assert_eq!(msg.descriptor().full_name(), "fuzzcase.Status");
        }
    }
}

#[test]
fn id_codec_on_a_field() {
    for dir in case_dirs("id-codec-on-a-field") {
        let (codec, pool, _) = load(&dir, "case.proto");
        let name = only_loaded(&codec, &dir);
        check_encodings(&dir, &codec, &pool, &name, "input.txt", "expected.hex");
    }
}

#[test]
fn legacy_options_import_path() {
    for dir in case_dirs("legacy-options-import-path") {
        let (codec, pool, _) = load(&dir, "case.proto");
        let name = only_loaded(&codec, &dir);
        check_encodings(&dir, &codec, &pool, &name, "input.txt", "expected.hex");
    }
}

#[test]
fn repeated_field_in_head() {
    for dir in case_dirs("repeated-field-in-head") {
        let expected = read(&dir, "expected.txt");
        let reason = expected
            .trim()
            .strip_prefix("refused at load: ")
            .expect("expected.txt starts with `refused at load: `");
        let pool = dccl::compile_protos(&[dir.join("case.proto")], &[] as &[PathBuf]).unwrap();
        let desc = pool.get_message_by_name("fuzzcase.HeadRepeated").unwrap();
        match Codec::new().load(&desc) {
            Err(Error::Definition {
                location,
                reason: ours,
            }) => {
                assert_eq!(location.message, "fuzzcase.HeadRepeated");
                assert_eq!(location.field, "r");
                assert!(ours.contains(reason), "{ours:?} does not say {reason:?}");
            }
            other => panic!("{}: loaded or other error: {other:?}", dir.display()),
        }
    }
}

#[test]
fn omit_id_decode() {
    for dir in case_dirs("omit-id-decode") {
        let (codec, pool, _) = load(&dir, "case.proto");
        let name = only_loaded(&codec, &dir);
        check_encodings(&dir, &codec, &pool, &name, "input.txt", "expected.hex");
        // Without a type name the bytes are read as an id, which is not this type.
        for hex in lines(&read(&dir, "expected.hex")) {
            let bytes = hex::decode(hex).unwrap();
            assert!(codec.decode(&bytes).is_err());
        }
    }
}

#[test]
fn stitched_frame_on_one_hex_line() {
    for dir in case_dirs("stitched-frame-on-one-hex-line") {
        let (codec, pool, _) = load(&dir, "case.proto");
        let name = only_loaded(&codec, &dir);
        let desc = pool.get_message_by_name(&name).unwrap();
        let frame = hex::decode(read(&dir, "input.hex").trim()).unwrap();
        let decoded = codec.decode_all(&frame).unwrap();
        let expected: Vec<DynamicMessage> = lines(&read(&dir, "expected.txt"))
            .into_iter()
            .map(|t| DynamicMessage::parse_text_format(desc.clone(), t).unwrap())
            .collect();
        assert_eq!(decoded, expected, "{}", dir.display());

        let garbage = hex::decode(read(&dir, "trailing-garbage.hex").trim()).unwrap();
        let err = codec.decode_all(&garbage).unwrap_err().to_string();
        assert!(
            err.contains(&format!("byte {}", frame.len())) && err.contains("2 messages"),
            "the error says where the leftover bytes start: {err}"
        );
    }
}

#[test]
fn analyze_codec_names() {
    for dir in case_dirs("analyze-codec-names") {
        let (codec, _, _) = load(&dir, "case.proto");
        let name = only_loaded(&codec, &dir);
        let ours = codec.analyze(&name).unwrap();
        let expected = read(&dir, "expected-analyze.txt");
        assert_eq!(ours.trim_end(), expected.trim_end(), "{}", dir.display());
    }
}

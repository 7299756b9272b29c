//! `Codec::analyze` against the reference `analyze` output of
//! `../shared/dccl-vectors/analyze.txt`, every line including the title with
//! the definition hash, and `Codec::hash` against `hashes.txt`.

use std::path::PathBuf;

use dccl::Codec;

fn vectors_dir() -> PathBuf {
    // ../shared beside the project when present, else the committed copy.
    let root = PathBuf::from(env!("CARGO_MANIFEST_DIR"));
    let shared = root.join("../../shared/dccl-vectors");
    if shared.is_dir() {
        shared
    } else {
        root.join("tests/data/dccl-vectors")
    }
}

#[test]
fn analyze_matches_reference_layout() {
    let mut codec = Codec::new();
    for proto in ["vectors.proto", "legacy.proto"] {
        let pool = dccl::compile_protos(&[vectors_dir().join(proto)], &[] as &[PathBuf]).unwrap();
        codec.load_file_messages(&pool, proto).unwrap();
    }
    let reference = std::fs::read_to_string(vectors_dir().join("analyze.txt")).unwrap();
    // Split the reference into one section per message (title lines start with '=').
    let mut sections: Vec<Vec<&str>> = Vec::new();
    for line in reference.lines() {
        if line.starts_with("==") {
            sections.push(Vec::new());
        }
        if let Some(s) = sections.last_mut() {
            s.push(line);
        }
    }
    assert_eq!(sections.len(), 7);
    for section in sections {
        let title = section[0];
        let name = title
            .split_whitespace()
            .find(|w| w.contains('.'))
            .expect("title names the message");
        let ours = codec.analyze(name).unwrap();
        let ours: Vec<String> = ours.lines().map(str::to_string).collect();
        assert_eq!(ours[0], title, "title of {name}");
        let expected: Vec<String> = section[1..].iter().map(|s| s.to_string()).collect();
        assert_eq!(&ours[1..], &expected[..], "analyze of {name}");
    }
}

#[test]
fn hashes_match_the_reference() {
    let mut codec = Codec::new();
    for proto in ["vectors.proto", "legacy.proto"] {
        let pool = dccl::compile_protos(&[vectors_dir().join(proto)], &[] as &[PathBuf]).unwrap();
        codec.load_file_messages(&pool, proto).unwrap();
    }
    let reference = std::fs::read_to_string(vectors_dir().join("hashes.txt")).unwrap();
    let mut checked = 0;
    for line in reference.lines().filter(|l| !l.trim().is_empty()) {
        let (name, hash) = line.split_once(' ').expect("`name 0xhash` lines");
        let ours = codec.hash(name).unwrap();
        assert_eq!(format!("{ours:#018x}"), hash.trim(), "{name}");
        checked += 1;
    }
    assert_eq!(checked, 7);
}

#[test]
fn field_sizes_match_the_reference_report() {
    let mut codec = Codec::new();
    let pool =
        dccl::compile_protos(&[vectors_dir().join("vectors.proto")], &[] as &[PathBuf]).unwrap();
    codec.load_file_messages(&pool, "vectors.proto").unwrap();
    let sizes = codec.field_sizes("vec.Nested").unwrap();
    let find = |p: &str| sizes.iter().find(|s| s.path == p).unwrap().clone();
    // From analyze.txt: pos 49, goal 1-50, track[3] 2-149, note 3-51, pos.x 18.
    assert_eq!((find("pos").min_bits, find("pos").max_bits), (49, 49));
    assert_eq!((find("goal").min_bits, find("goal").max_bits), (1, 50));
    assert_eq!((find("track").min_bits, find("track").max_bits), (2, 149));
    assert_eq!((find("note").min_bits, find("note").max_bits), (3, 51));
    assert_eq!(find("pos.x").max_bits, 18);
    assert_eq!(find("pos.x").codec, "dccl.default4");
    let wide = codec.field_sizes("vec.Wide").unwrap();
    assert_eq!(wide[0].path, "src");
    assert_eq!(wide[0].part, dccl::MessagePart::Head);
    assert_eq!(wide[2].part, dccl::MessagePart::Body);
    assert!(codec.field_sizes("vec.Nope").is_err());
    assert_eq!(codec.min_size("vec.Nested").unwrap(), 1 + 7);
    assert_eq!(codec.max_size("vec.Nested").unwrap(), 39);
}

//! Called by another name (the Debian package's `goby-rs` link), goby
//! writes its manual pages and completions for that name.

use std::process::Command;

#[test]
fn pages_and_completions_follow_the_name_goby_is_called_by() {
    let dir = std::env::temp_dir().join(format!("goby-called-name-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("goby-rs");
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_goby"), &link).unwrap();
    let out = Command::new(&link)
        .arg("man")
        .arg(dir.join("man1"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    for page in ["goby-rs.1", "goby-rs-dccl.1", "goby-rs-dccl-wireshark.1"] {
        let text = std::fs::read_to_string(dir.join("man1").join(page)).unwrap();
        assert!(text.contains("goby\\-rs"), "{page}: {text}");
    }
    assert!(!dir.join("man1/goby.1").exists());
    let out = Command::new(&link)
        .args(["completions", "bash"])
        .output()
        .unwrap();
    let script = String::from_utf8(out.stdout).unwrap();
    assert!(script.contains("default goby-rs\n"), "{script}");
    let _ = std::fs::remove_dir_all(&dir);
}

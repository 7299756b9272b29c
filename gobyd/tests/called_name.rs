//! Called by another name (the Debian package's `gobyd-rs` link), gobyd
//! writes its manual page and completions for that name.

use std::process::Command;

#[test]
fn page_and_completions_follow_the_name_gobyd_is_called_by() {
    let dir = std::env::temp_dir().join(format!("gobyd-called-name-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let link = dir.join("gobyd-rs");
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_gobyd"), &link).unwrap();
    let out = Command::new(&link)
        .arg("--man")
        .arg(dir.join("man1"))
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let page = std::fs::read_to_string(dir.join("man1/gobyd-rs.1")).unwrap();
    assert!(
        page.contains(".TH gobyd\\-rs") || page.contains(".TH gobyd-rs"),
        "{page}"
    );
    let out = Command::new(&link)
        .args(["--completions", "bash"])
        .output()
        .unwrap();
    let script = String::from_utf8(out.stdout).unwrap();
    assert!(script.contains("default gobyd-rs\n"), "{script}");
    let _ = std::fs::remove_dir_all(&dir);
}

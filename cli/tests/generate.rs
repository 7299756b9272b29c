//! `goby completions SHELL` and `goby man DIR` as processes: scripts for
//! every shell clap knows, manual pages with every subcommand's options.

use std::path::PathBuf;
use std::process::Output;

fn goby(args: &[&str]) -> Output {
    assert_cmd::Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap()
}

fn text(bytes: &[u8]) -> String {
    String::from_utf8_lossy(bytes).into_owned()
}

#[test]
fn completion_scripts_name_the_subcommands_and_their_options() {
    let out = goby(&["completions", "bash"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let bash = text(&out.stdout);
    for word in [
        "dccl",
        "amac",
        "queue",
        "position",
        "modem",
        "mqtt",
        "console",
        "--origin",
        "moos",
        "poke",
        "spy",
        "completions",
        "man",
        "--connect-timeout",
        "--moos-file",
        "--broker",
    ] {
        assert!(bash.contains(word), "{word} missing from the bash script");
    }
    assert!(
        bash.contains("goby__subcmd__moos__subcmd__spy)"),
        "no case for goby moos spy"
    );
    for shell in ["zsh", "fish", "elvish", "powershell"] {
        let out = goby(&["completions", shell]);
        assert!(out.status.success(), "{shell}: {}", text(&out.stderr));
        let script = text(&out.stdout);
        assert!(
            script.contains("poke") && script.contains("connect-timeout"),
            "{shell}: {script}"
        );
    }
}

#[test]
fn an_unknown_shell_is_refused_with_the_known_ones() {
    let out = goby(&["completions", "tcsh"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(out.stdout.is_empty());
    let err = text(&out.stderr);
    assert!(
        err.contains("invalid value 'tcsh' for '<SHELL>'")
            && err.contains("[possible values: bash, elvish, fish, powershell, zsh]"),
        "{err}"
    );
}

#[test]
fn man_writes_a_page_per_subcommand_with_its_options() {
    let dir = std::env::temp_dir()
        .join(format!("goby-man-{}", std::process::id()))
        .join("man1");
    let _ = std::fs::remove_dir_all(&dir);
    let out = goby(&["man", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    let listed: Vec<PathBuf> = text(&out.stdout).lines().map(PathBuf::from).collect();
    let mut on_disk: Vec<PathBuf> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .collect();
    on_disk.sort();
    let mut sorted = listed.clone();
    sorted.sort();
    assert_eq!(sorted, on_disk, "the pages printed are the pages written");
    assert_eq!(listed[0], dir.join("goby.1"));
    for (page, options) in [
        ("goby.1", &["goby\\-moos(1)", "goby\\-completions(1)"][..]),
        ("goby-dccl.1", &["encode"]),
        ("goby-dccl-encode.1", &["\\-\\-message"]),
        ("goby-mqtt-watch.1", &["\\-\\-broker", "\\-\\-once"]),
        (
            "goby-console.1",
            &["\\-\\-origin", "\\-\\-gobyd", "\\-\\-listen"],
        ),
        (
            "goby-moos-poke.1",
            &[
                "\\-\\-string",
                "\\-\\-moos\\-file",
                "\\-\\-connect\\-timeout",
                "uPokeDB",
            ],
        ),
        (
            "goby-moos-spy.1",
            &["\\-\\-count", "\\-\\-timeout", "\\-\\-verbose"],
        ),
        (
            "goby-file-send.1",
            &["\\-\\-gobyd", "\\-\\-timeout", "127.0.0.1:11145"],
        ),
        ("goby-file-get.1", &["\\-\\-output", "serve_dir"]),
        ("goby-completions.1", &["powershell"]),
        ("goby-man.1", &["DIR"]),
    ] {
        let text =
            std::fs::read_to_string(dir.join(page)).unwrap_or_else(|e| panic!("{page}: {e}"));
        assert!(text.contains(".TH "), "{page} is not a man page");
        for option in options {
            assert!(
                text.contains(option),
                "{option} missing from {page}:\n{text}"
            );
        }
    }
    for path in &on_disk {
        assert!(
            std::fs::metadata(path).unwrap().len() > 0,
            "{path:?} is empty"
        );
    }
    // The help texts' Markdown code spans are shown in bold, not as
    // backticks.
    for path in &on_disk {
        let page = std::fs::read_to_string(path).unwrap();
        assert!(!page.contains('`'), "{path:?} shows a backtick:\n{page}");
    }
    assert!(!dir.join("goby-help.1").exists());
    let _ = std::fs::remove_dir_all(dir.parent().unwrap());

    let out = goby(&["man", "/dev/null/man1"]);
    assert_eq!(out.status.code(), Some(2));
    let err = text(&out.stderr);
    assert!(
        err.contains("cannot create the directory /dev/null/man1"),
        "{err}"
    );
}

/// The installing commands of `docs/README.md` (completions and manual
/// pages), as written, for a user whose `goby` is in `~/.cargo/bin`: they
/// work in a fresh home, and `man` finds the pages without a MANPATH.
#[test]
fn the_documented_installing_commands_work_in_a_fresh_home() {
    let home = std::env::temp_dir().join(format!("goby-install-home-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&home);
    let bin = home.join(".cargo/bin");
    std::fs::create_dir_all(&bin).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_goby"), bin.join("goby")).unwrap();
    let path = format!("{}:/usr/local/bin:/usr/bin:/bin", bin.display());
    let script = guide_check::installing_commands("goby");
    assert!(script.contains("goby man "), "{script}");
    let out = std::process::Command::new("bash")
        .args(["-e", "-c", &script])
        .env_clear()
        .env("HOME", &home)
        .env("PATH", &path)
        .output()
        .unwrap();
    assert!(
        out.status.success(),
        "{script}\n{}{}",
        text(&out.stdout),
        text(&out.stderr)
    );
    for written in [
        ".local/share/bash-completion/completions/goby",
        ".zfunc/_goby",
        ".config/fish/completions/goby.fish",
        ".cargo/share/man/man1/goby.1",
        ".cargo/share/man/man1/goby-moos-spy.1",
    ] {
        let len = std::fs::metadata(home.join(written))
            .unwrap_or_else(|e| panic!("{written}: {e}"))
            .len();
        assert!(len > 0, "{written} is empty");
    }
    // man-db looks in ../share/man beside each PATH directory.
    let have_man = std::process::Command::new("sh")
        .args(["-c", "command -v man"])
        .output()
        .is_ok_and(|o| o.status.success());
    if have_man {
        let out = std::process::Command::new("man")
            .args(["-w", "goby", "goby-moos-spy"])
            .env_clear()
            .env("HOME", &home)
            .env("PATH", &path)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", text(&out.stderr));
        let found = text(&out.stdout);
        let pages = home.join(".cargo/share/man/man1");
        for page in ["goby.1", "goby-moos-spy.1"] {
            assert!(
                found.contains(&pages.join(page).display().to_string()),
                "man -w: {found}"
            );
        }
    } else {
        eprintln!("man is not installed: where man finds the pages is not checked");
    }
    let _ = std::fs::remove_dir_all(&home);
}

//! A configuration of Goby3's own `gobyd` (its middleware daemon:
//! `interprocess`, `router_threads`, `intervehicle`, ...) given to this
//! `gobyd` is recognised: the error says what this daemon is and which
//! Goby3 blocks it takes instead, whichever of Goby3's keys comes first.

use std::path::Path;
use std::process::Command;

/// A Goby3 `gobyd` configuration as a vehicle running Goby3 has it: the
/// middleware's interprocess settings, router threads and an intervehicle
/// portal with one UDP multicast link.
const GOBY3_GOBYD: &str = r#"
interprocess {
  platform: "auv1"
  transport: IPC
}
router_threads: 4
intervehicle {
  link {
    modem_id: 1
    subnet_mask: 0xFFF0
    driver {
      driver_type: DRIVER_UDP_MULTICAST
      [goby.acomms.udp_multicast.protobuf.config] { listen_address: "0.0.0.0" multicast_address: "239.142.0.1" multicast_port: 50031 }
    }
    mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 slot_seconds: 5 } }
  }
}
"#;

fn check(dir: &Path, name: &str, text: &str) -> (bool, String) {
    let path = dir.join(name);
    std::fs::write(&path, text).unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .arg("--check")
        .arg("-c")
        .arg(&path)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("gobyd runs");
    (
        out.status.success(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

fn scratch(name: &str) -> std::path::PathBuf {
    let dir =
        std::env::temp_dir().join(format!("gobyd-goby3-daemon-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// The error names Goby3's daemon, says what this one is, and which blocks
/// it takes instead (a pAcommsHandler block, the intervehicle links'
/// driver and mac as `link` sections, the queue settings).
fn assert_recognised(stderr: &str, key: &str) {
    let not_found = format!("field '{key}' not found");
    for wanted in [
        not_found.as_str(),
        "Goby3's gobyd",
        "middleware daemon",
        "pAcommsHandler",
        "driver_cfg",
        "link {",
        "driver {",
        "mac {",
        "queue {",
        "docs/goby3.md",
    ] {
        assert!(
            stderr.contains(wanted),
            "the error should say {wanted:?}:\n{stderr}"
        );
    }
}

#[test]
fn a_goby3_gobyd_configuration_is_recognised() {
    let dir = scratch("interprocess");
    let (ok, stderr) = check(&dir, "goby3-gobyd.pb.txt", GOBY3_GOBYD);
    assert!(!ok, "refused");
    assert!(stderr.starts_with("gobyd: error: "), "{stderr}");
    assert_recognised(&stderr, "interprocess");
    // Where it is written: the first of Goby3's keys.
    assert!(stderr.contains("goby3-gobyd.pb.txt:2:1"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn each_top_level_key_of_goby3s_daemon_is_recognised() {
    let dir = scratch("keys");
    for (key, text) in [
        ("router_threads", "router_threads: 10\n"),
        ("intervehicle", "intervehicle { link { modem_id: 2 } }\n"),
        (
            "app",
            "app { name: \"gobyd\" }\ninterprocess { platform: \"auv1\" }\n",
        ),
        ("hold", "hold { required_client: \"goby_logger\" }\n"),
    ] {
        let (ok, stderr) = check(&dir, &format!("{key}.pb.txt"), text);
        assert!(!ok, "{key}: refused");
        assert_recognised(&stderr, key);
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// A key that is neither gobyd's nor Goby3's daemon's gets the parser's
/// plain reason, without the Goby3 hint.
#[test]
fn other_unknown_keys_are_not_taken_for_goby3s_daemon() {
    let dir = scratch("other");
    let (ok, stderr) = check(&dir, "other.pb.txt", "no_such_setting: 3\n");
    assert!(!ok);
    assert!(
        stderr.contains("field 'no_such_setting' not found"),
        "{stderr}"
    );
    assert!(!stderr.contains("Goby3's gobyd"), "{stderr}");
    let _ = std::fs::remove_dir_all(&dir);
}

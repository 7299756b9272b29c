//! `gobyd --check` says everything it can see in one run: every key the
//! configuration does not have (top-level and nested, Goby3's daemon's
//! included), every Goby key it cannot map, and every clash on this
//! machine: the data directory held by another daemon, the JSON port
//! taken, another configuration in the same directory sharing the default
//! data directory.

use std::path::Path;
use std::process::Output;

fn scratch(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("gobyd-check-once-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// `gobyd --check -c FILE` run in `dir` (where the default data
/// directory `gobyd-data` is).
fn check(dir: &Path, file: &str) -> Output {
    std::process::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(["--check", "-c", file])
        .current_dir(dir)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("gobyd runs")
}

/// The default data directory of `dir`, its lock held as a running daemon
/// holds it (with this process's id in it).
fn hold_default_data_dir(dir: &Path) -> std::fs::File {
    use std::io::Write;
    let data = dir.join("gobyd-data");
    std::fs::create_dir_all(&data).unwrap();
    let mut lock = std::fs::File::create(data.join("gobyd.lock")).unwrap();
    lock.try_lock().unwrap();
    writeln!(lock, "{}", std::process::id()).unwrap();
    lock
}

#[test]
fn unknown_keys_unmappable_keys_and_clashes_are_all_told_in_one_run() {
    let dir = scratch("all");
    let port = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let taken = port.local_addr().unwrap();
    let config = format!(
        "modem_id: 1\n\
         frobnicate: 1\n\
         interprocess {{ platform: \"auv\" }}\n\
         queue {{ skip_decoding: true }}\n\
         load_shared_library: \"libnav.so\"\n\
         json {{ tcp_bind: \"{taken}\" }}\n\
         common {{ time_warp_multiplier: 10 }}\n"
    );
    std::fs::write(dir.join("alpha.pb.txt"), &config).unwrap();
    // A second pasted block in the same directory, data_dir unset too.
    std::fs::write(
        dir.join("bravo.pb.txt"),
        "modem_id: 2\ndriver_cfg { driver_type: DRIVER_UDP }\n",
    )
    .unwrap();
    let _held = hold_default_data_dir(&dir);
    let out = check(&dir, "alpha.pb.txt");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(2), "{err}");
    for (what, wanted) in [
        (
            "an unknown key",
            "alpha.pb.txt:2:1: frobnicate: field 'frobnicate' not found",
        ),
        (
            "Goby3's daemon",
            "alpha.pb.txt:3:1: interprocess: field 'interprocess' not found",
        ),
        ("the hint for Goby3's daemon", "Goby3's gobyd"),
        (
            "a nested unknown key",
            "alpha.pb.txt:4:9: skip_decoding: field 'skip_decoding' not found",
        ),
        (
            "an unmappable Goby key",
            "alpha.pb.txt:5:1: load_shared_library[0]: gobyd loads no C++ libraries",
        ),
        ("another", "alpha.pb.txt:7:10: common.time_warp_multiplier"),
        (
            "the data directory held",
            "clash: data_dir: \"gobyd-data\" is in use by another gobyd",
        ),
        ("the holder", &format!("(pid {})", std::process::id())),
        (
            "the port taken",
            &format!("clash: json.tcp_bind: \"{taken}\" is taken"),
        ),
        (
            "the shared default",
            "warning: clash: data_dir: not set, and not set in ./bravo.pb.txt either",
        ),
    ] {
        assert!(err.contains(wanted), "{what}: {wanted:?} not in\n{err}");
    }
    assert!(
        err.starts_with("gobyd: error: configuration: 5 settings cannot work:"),
        "{err}"
    );

    // A configuration that is right by itself: the clashes are told as
    // warnings (what holds the lock and the port now may be gone when the
    // daemon starts), and the configuration is valid.
    std::fs::write(
        dir.join("alpha.pb.txt"),
        format!("modem_id: 1\njson {{ tcp_bind: \"{taken}\" }}\n"),
    )
    .unwrap();
    let out = check(&dir, "alpha.pb.txt");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(
        err.contains("warning: clash: data_dir: \"gobyd-data\" is in use")
            && err.contains("warning: clash: json.tcp_bind:")
            && err.contains("a daemon started now would stop here"),
        "{err}"
    );
    drop(port);
    drop(_held);
    // Nothing in the way: accepted, the shared default a warning.
    let out = check(&dir, "alpha.pb.txt");
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(0), "{err}");
    assert!(err.contains("warning: clash: data_dir: not set"), "{err}");
    assert!(!err.contains("error"), "{err}");
    // An address no interface here has (a documentation address, never
    // this machine's; nothing is sent to it): told, as a daemon started
    // now would stop.
    std::fs::write(
        dir.join("alpha.pb.txt"),
        "modem_id: 1\njson { tcp_bind: \"192.0.2.1:47397\" }\n",
    )
    .unwrap();
    let out = check(&dir, "alpha.pb.txt");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(
            "warning: clash: json.tcp_bind: \"192.0.2.1:47397\" is not an address of this machine now"
        ),
        "{err}"
    );
    // A link's UDP driver on a port another program holds.
    let udp = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let held = udp.local_addr().unwrap();
    std::fs::write(
        dir.join("alpha.pb.txt"),
        format!(
            "modem_id: 1\nlink {{ name: \"radio\" driver {{ driver_type: DRIVER_UDP \
             udp {{ local {{ port: {} }} remote {{ modem_id: 2 port: 9 }} }} }} }}\n",
            held.port()
        ),
    )
    .unwrap();
    let out = check(&dir, "alpha.pb.txt");
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(
        err.contains(&format!(
            "warning: clash: link[0].driver.udp.local: \"{held}\" is taken"
        )),
        "{err}"
    );
    drop(udp);
    std::fs::remove_dir_all(&dir).unwrap();
}

//! The `gobyd` command line: version, the example and shipped
//! configurations, and bad configurations refused with their place.

mod support;

use std::path::PathBuf;
use std::process::Output;
use support::daemon::scratch;

/// Root of the workspace.
fn workspace_dir() -> PathBuf {
    PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/.."))
}

fn stdout_text(out: &Output) -> String {
    String::from_utf8(out.stdout.clone()).expect("stdout is UTF-8")
}

fn stderr_text(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn version() {
    let out = gobyd(&["--version"]);
    assert!(out.status.success());
    assert_eq!(
        stdout_text(&out).trim(),
        format!("gobyd {}", env!("CARGO_PKG_VERSION"))
    );
}

/// A pseudo-terminal standing for a modem's serial port, open while the
/// value lives (a configuration naming a port that does not exist is
/// refused).
struct SerialPort {
    _runtime: tokio::runtime::Runtime,
    pty: modemdriver::link::serial::PtyPair,
}

impl SerialPort {
    fn open() -> Self {
        let runtime = tokio::runtime::Builder::new_current_thread()
            .enable_all()
            .build()
            .unwrap();
        let pty = runtime
            .block_on(async { modemdriver::link::serial::open_pty_pair() })
            .expect("a pseudo-terminal");
        SerialPort {
            _runtime: runtime,
            pty,
        }
    }

    /// `text` with the placeholder port `/dev/ttyUSB0` made this one.
    fn with_port(&self, text: &str) -> String {
        text.replace("/dev/ttyUSB0", &self.pty.path)
    }
}

fn gobyd(args: &[&str]) -> std::process::Output {
    assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("gobyd runs")
}

#[test]
fn gobyd_example_and_shipped_configurations_check_out() {
    let out = gobyd(&["--example-config"]);
    assert!(out.status.success());
    let example = stdout_text(&out);
    assert!(example.contains("modem_id: 1"), "{example}");
    let dir = scratch("command", "gobyd-config");
    let path = dir.join("example.pb.txt");
    std::fs::write(&path, &example).unwrap();
    let mut configs = vec![path.to_str().unwrap().to_string()];
    for v in ["vehicle1", "vehicle2"] {
        let p = workspace_dir()
            .join("gobyd/config")
            .join(format!("{v}.pb.txt"));
        configs.push(p.to_str().unwrap().to_string());
    }
    for config in &configs {
        let out = gobyd(&["--check", "--config", config]);
        assert!(out.status.success(), "{config}: {}", stderr_text(&out));
        assert_eq!(
            stdout_text(&out).trim(),
            "configuration is valid; DCCL types: goby.example.Command, goby.example.NavigationReport"
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn gobyd_refuses_bad_configurations_with_their_place() {
    let dir = scratch("command", "gobyd-bad");
    for (text, expected) in [
        ("modem_id: \"one\"", "bad.pb.txt:"),
        ("no_such_setting: 1", "no_such_setting"),
        ("modem_id: 0", "bad.pb.txt:1:1: modem_id: 0 is not valid"),
        (
            "queue { message_entry { protobuf_name: \"goby.example.Nope\" } }",
            "goby.example.Nope",
        ),
        (
            "mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 slot_seconds: -1 } }",
            "bad.pb.txt:1:51: mac.slot[0].slot_seconds: must be a finite number",
        ),
        (
            "queue { hold_retry_until_heard: true }",
            "bad.pb.txt:1:9: queue.hold_retry_until_heard: hold_retry_until_heard is true but \
             hold_retry_max_seconds is not set",
        ),
        (
            "queue { hold_retry_until_heard: true hold_retry_max_seconds: -1 }",
            "bad.pb.txt:1:38: queue.hold_retry_max_seconds: hold_retry_max_seconds -1 is not valid",
        ),
    ] {
        let path = dir.join("bad.pb.txt");
        std::fs::write(&path, text).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{text}");
        let err = stderr_text(&out);
        assert!(
            err.starts_with("gobyd: error: ") && err.contains(expected),
            "{text}: {err}"
        );
    }
    let out = gobyd(&["--config", "/no/such/file.pb.txt"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_text(&out).contains("cannot read /no/such/file.pb.txt"));
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn configuration_errors_give_file_line_and_column() {
    let dir = scratch("command", "gobyd-position");
    for (text, expected) in [
        (
            "modem_id: 1\nmac {\n  type: MAC_NONE\n  bogus: 3\n}\n",
            "bad.pb.txt:4:3: ",
        ),
        ("modem_id: 1\n\n   modem_id: \"one\"\n", "bad.pb.txt:3:14: "),
        (
            "driver {\n  driver_type: DRIVER_UDP\n  [goby.acomms.nope.protobuf.config] { }\n}\n",
            "bad.pb.txt:3:",
        ),
        // A Goby3 Micro-Modem setting this driver does not have.
        (
            "driver_cfg {\n  driver_type: DRIVER_WHOI_MICROMODEM\n  [goby.acomms.micromodem.protobuf.config] {\n    reset_nvram: true\n    hydroid_gateway_id: 1\n  }\n}\n",
            "bad.pb.txt:5:5: ",
        ),
    ] {
        let path = dir.join("bad.pb.txt");
        std::fs::write(&path, text).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{text}");
        let err = stderr_text(&out);
        assert!(err.contains(expected), "{text}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_refuses_a_modem_id_with_no_mac_slot() {
    let dir = scratch("command", "gobyd-noslot");
    let path = dir.join("noslot.pb.txt");
    std::fs::write(
        &path,
        "modem_id: 3\nmac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 slot_seconds: 5 } slot { src: 2 slot_seconds: 5 } }\n",
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(
        err.contains("modem_id 3 has no slot") && err.contains("1, 2"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_refuses_settings_that_cannot_work() {
    let port = SerialPort::open();
    let dir = scratch("command", "gobyd-cannot-work");
    let path = dir.join("bad.pb.txt");
    for (text, expected) in [
        (
            "modem_id: 1\nmac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 rate: 9 slot_seconds: 10 } }\n",
            "mac.slot[0].rate: 9 is not a Micro-Modem rate",
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\" }\n\
             mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 rate: 1 slot_seconds: 5 } }\n",
            "mac.slot[0].slot_seconds: 5 s is too short for a rate-1 packet of 3 frames on the Micro-Modem (needs at least 7.3 s",
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM }\n",
            "driver.serial_port: required for the Micro-Modem",
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\" \
             micromodem { nvram_cfg: \"$CCCFG,DQF,1\" } }\n",
            "give KEY,VALUE",
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\" \
             micromodem { response_timeout_ms: 0 } }\n",
            "driver.micromodem.response_timeout_ms: must be positive",
        ),
        (
            "modem_id: 1\nlog { level: \"warning\" }\n",
            "log.level: \"warning\" is not a level",
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\" \
             micromodem { nvram_cfg: \"SRC,5\" } }\n",
            "driver.micromodem.nvram_cfg[0]: \"SRC,5\" sets the modem's address to 5 but modem_id is 1",
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\" \
             micromodem { application_ack_lifetime_seconds: 30 } }\n\
             mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 rate: 1 slot_seconds: 10 } slot { src: 2 rate: 1 slot_seconds: 10 } }\n",
            "driver.micromodem.application_ack_lifetime_seconds: 30 s is shorter than two TDMA cycles (the cycle lasts 20 s)",
        ),
        (
            "modem_id: 2\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\" modem_id: 1 }\n",
            "driver.modem_id: 1 differs from modem_id 2",
        ),
        (
            "modem_id: 40\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\" }\n",
            "modem_id 40: the Micro-Modem's application acks name nodes 0-31",
        ),
        (
            "modem_id: 1\njson { tcp_bind: \"127.0.0.1:99999\" }\n",
            "json.tcp_bind: \"127.0.0.1:99999\" is not an address",
        ),
        (
            "modem_id: 1\njson { tcp_bind: \"localhost\" }\n",
            "json.tcp_bind: \"localhost\" is not an address",
        ),
    ] {
        std::fs::write(&path, port.with_port(text)).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{text}");
        let err = stderr_text(&out);
        assert!(err.contains(expected), "{text}: {err}");
        // Each case has the one problem it is written for.
        assert!(!err.contains("settings cannot work"), "{text}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `modem_id: 0`, `.proto` files that are not there and a serial port
/// that is not a terminal are told with their place in the file, as every
/// other problem is.
#[test]
fn check_places_the_modem_id_the_proto_files_and_the_serial_port() {
    let dir = scratch("command", "gobyd-places");
    let path = dir.join("bad.pb.txt");
    let plain = dir.join("plain-file");
    std::fs::write(&plain, "").unwrap();
    let micromodem = |port: &str| {
        format!(
            "modem_id: 1\ndriver {{\n  driver_type: DRIVER_WHOI_MICROMODEM\n  serial_port: \"{port}\"\n}}\n"
        )
    };
    for (text, expected) in [
        (
            "# node\n  modem_id: 0\n".to_string(),
            vec!["bad.pb.txt:2:3: modem_id: 0 is not valid: modem ids are 1 and up (0 is broadcast)"],
        ),
        (
            "modem_id: 2\nqueue {\n  modem_id: 3\n}\n".to_string(),
            vec!["bad.pb.txt:3:3: queue.modem_id: 3 differs from modem_id 2"],
        ),
        (
            format!(
                "modem_id: 1\ndccl {{\n  proto_file: \"/no/such.proto\"\n  proto_file: \"{}\"\n}}\n",
                dir.display()
            ),
            vec![
                "bad.pb.txt:3:3: dccl.proto_file[0]: /no/such.proto: no such file",
                "bad.pb.txt:4:3: dccl.proto_file[1]: ",
                ": a directory, not a .proto file",
            ],
        ),
        (
            micromodem("/dev/null"),
            vec![
                "bad.pb.txt:4:3: driver.serial_port: \"/dev/null\" is not a serial port: it is a \
                 character device of class \"mem\", not a terminal (tty)",
            ],
        ),
        (
            micromodem(plain.to_str().unwrap()),
            vec!["bad.pb.txt:4:3: driver.serial_port: ", "is not a serial port (not a character device"],
        ),
    ] {
        std::fs::write(&path, &text).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        assert_eq!(out.status.code(), Some(2), "{text}");
        let err = stderr_text(&out);
        for part in expected {
            assert!(err.contains(part), "{text}: {err}");
        }
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_refuses_a_dccl_id_the_application_acks_take() {
    let dir = scratch("command", "gobyd-app-ack-id");
    let proto = dir.join("status.proto");
    std::fs::write(
        &proto,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage test;\n\
         message Status {\n  option (dccl.msg) = { id: 10 max_bytes: 32 codec_version: 4 };\n\
         optional int32 depth = 1 [(dccl.field) = { min: 0 max: 100 }];\n}\n",
    )
    .unwrap();
    let path = dir.join("mm.pb.txt");
    let config = |driver: &str| {
        format!(
            "modem_id: 1\ndccl {{ proto_file: \"{}\" }}\ndriver {{ {driver} }}\n\
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 rate: 1 slot_seconds: 10 }} }}\n",
            proto.display()
        )
    };
    let port = SerialPort::open();
    let mm = &port.with_port("driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/ttyUSB0\"");
    std::fs::write(&path, config(mm)).unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(
        err.contains("test.Status has DCCL id 10, which the Micro-Modem's application acks take"),
        "{err}"
    );
    // Without application acks, or over another driver, the id is free.
    for driver in [
        format!("{mm} micromodem {{ use_application_acks: false }}"),
        "driver_type: DRIVER_UDP udp { local { port: 50001 } }".to_string(),
    ] {
        std::fs::write(&path, config(&driver)).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        assert!(out.status.success(), "{driver}: {}", stderr_text(&out));
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn driver_sections_written_as_goby3_writes_them_are_read() {
    let dir = scratch("command", "gobyd-goby3");
    let path = dir.join("goby3.pb.txt");
    // As a goby_modemdriver / pAcommsHandler configuration writes them.
    std::fs::write(
        &path,
        r#"modem_id: 1
driver_cfg {
  driver_type: DRIVER_UDP
  [goby.acomms.udp.protobuf.config] {  # the UDP driver's settings
    local { port: 50001 }
    remote { modem_id: 2 ip: "127.0.0.1" port: 50002 }
    max_frame_size: 64
  }
}
mac_cfg {
  type: MAC_FIXED_DECENTRALIZED
  slot { src: 1 dest: -1 slot_seconds: 5 }
  slot { src: 2 dest: -1 slot_seconds: 5 }
}
queue_cfg {
  message_entry { protobuf_name: "goby.example.Command" ack: true }
}
"#,
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr_text(&out));
    let mm = dir.join("mm.pb.txt");
    let port = SerialPort::open();
    std::fs::write(
        &mm,
        port.with_port(
            r#"modem_id: 1
driver_cfg {
  driver_type: DRIVER_WHOI_MICROMODEM
  serial_port: "/dev/ttyUSB0"
  [goby.acomms.micromodem.protobuf.config] {
    reset_nvram: true
    nvram_cfg: "DQF,1"
    keep_alive_seconds: 10
  }
}
"#,
        ),
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", mm.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr_text(&out));
    // Both names of one section: refused.
    std::fs::write(&mm, "driver {}\ndriver_cfg {}\n").unwrap();
    let out = gobyd(&["--check", "--config", mm.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    assert!(stderr_text(&out).contains("both driver and driver_cfg"));
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Goby3's Flexible Data Protocol slot, pasted from a pAcommsHandler
/// configuration (`[goby.acomms.micromodem.protobuf.transmission]`), reads
/// as gobyd's own (`micromodem { type: ... }`); `--check` says which
/// `use_application_acks` FDP slots need, and refuses DRIVER_SPECIFIC
/// slots that cannot work, naming the field and its place.
#[test]
fn check_reads_goby3_fdp_slots_and_says_what_they_need() {
    let port = SerialPort::open();
    let dir = scratch("command", "gobyd-fdp-slots");
    let path = dir.join("fdp.pb.txt");
    let mm =
        "driver_cfg {\n  driver_type: DRIVER_WHOI_MICROMODEM\n  serial_port: \"/dev/ttyUSB0\"\n";
    let config = |acks: &str, slot: &str| {
        port.with_port(&format!(
            "modem_id: 1\n{mm}{acks}}}\nmac_cfg {{\n  type: MAC_FIXED_DECENTRALIZED\n{slot}}}\n"
        ))
    };
    let goby3_slot = "  slot { src: 1 rate: 1 type: DRIVER_SPECIFIC [goby.acomms.micromodem.protobuf.transmission] { type: MICROMODEM_FLEXIBLE_DATA } slot_seconds: 10 }\n  slot { src: 2 rate: 1 type: DRIVER_SPECIFIC micromodem { type: MICROMODEM_FLEXIBLE_DATA } slot_seconds: 10 }\n";
    let acks_on = "  [goby.acomms.micromodem.protobuf.config] { use_application_acks: true }\n";
    let acks_off = "  [goby.acomms.micromodem.protobuf.config] { use_application_acks: false }\n";
    let check = |text: String| {
        std::fs::write(&path, &text).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        (out.status.code(), stderr_text(&out), text)
    };
    // Read, both names; with application acks, nothing to say.
    let (code, err, text) = check(config(acks_on, goby3_slot));
    assert_eq!(code, Some(0), "{text}: {err}");
    assert!(!err.contains("Flexible Data Protocol"), "{err}");
    // Left to gobyd's default: Goby3 nodes need them too.
    let (code, err, _) = check(config("", goby3_slot));
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("as its Flexible Data Protocol slots need")
            && err.contains("set use_application_acks: true in their"),
        "{err}"
    );
    // Without them: no ack, ever.
    let (code, err, _) = check(config(acks_off, goby3_slot));
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("fdp.pb.txt:9:3: mac.slot[0] is a Flexible Data Protocol slot and driver.micromodem.use_application_acks is false")
            && err.contains("no message sent in these slots is ever acknowledged"),
        "{err}"
    );
    // Data and FDP slots in one fleet with Goby3: application acks in FDP
    // packets only.
    let mixed = "  slot { src: 1 rate: 1 type: DRIVER_SPECIFIC micromodem { type: MICROMODEM_FLEXIBLE_DATA } slot_seconds: 10 }\n  slot { src: 2 rate: 1 slot_seconds: 10 }\n";
    let (code, err, _) = check(config("", mixed));
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("set application_acks: FDP_ONLY")
            && err.contains("a gobyd FDP slot between any two slots of a Goby3 node"),
        "{err}"
    );
    let (code, err, text) = check(config(
        "  micromodem { application_acks: FDP_ONLY }\n",
        mixed,
    ));
    assert_eq!(code, Some(0), "{text}: {err}");
    assert!(!err.contains("application_acks"), "{err}");
    // Set both ways, they must agree.
    let (code, err, _) = check(config(
        "  micromodem { application_acks: FDP_ONLY use_application_acks: false }\n",
        mixed,
    ));
    assert_ne!(code, Some(0), "{err}");
    assert!(
        err.contains("micromodem.application_acks") && err.contains("FDP_ONLY disagrees"),
        "{err}"
    );
    // NONE is not turned on by gobyd's default.
    let (code, err, _) = check(config(
        "  micromodem { application_acks: NONE }\n",
        goby3_slot,
    ));
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("driver.micromodem.application_acks is NONE: the modem acknowledges no FDP"),
        "{err}"
    );
    for (slot, expected) in [
        (
            "  slot { src: 1 rate: 2 type: DRIVER_SPECIFIC micromodem { type: MICROMODEM_FLEXIBLE_DATA } slot_seconds: 10 }\n",
            "fdp.pb.txt:9:17: mac.slot[0].rate: 2 is not a Flexible Data Protocol rate (1, 3 or 5)",
        ),
        (
            "  slot { src: 1 rate: 1 type: DRIVER_SPECIFIC slot_seconds: 10 }\n",
            "mac.slot[0].micromodem.type: required for a DRIVER_SPECIFIC transmission",
        ),
        (
            "  slot { src: 1 type: DRIVER_SPECIFIC micromodem { type: MICROMODEM_MINI_DATA } slot_seconds: 10 }\n",
            "mac.slot[0].micromodem.type: MICROMODEM_MINI_DATA is not sent from a slot",
        ),
        (
            "  slot { src: 1 type: DRIVER_SPECIFIC micromodem { type: MICROMODEM_TWO_WAY_PING } slot_seconds: 10 }\n",
            "mac.slot[0].dest: required (the modem to reach, 1-127)",
        ),
        (
            "  slot { src: 1 rate: 5 type: DRIVER_SPECIFIC micromodem { type: MICROMODEM_FLEXIBLE_DATA } slot_seconds: 3 }\n",
            "mac.slot[0].slot_seconds: 3 s is too short for a rate-5 packet of 8 frames",
        ),
    ] {
        let (code, err, text) = check(config(acks_on, slot));
        assert_eq!(code, Some(2), "{text}: {err}");
        assert!(err.contains(expected), "{text}: {err}");
    }
    // Another driver has no FDP.
    let (code, err, text) = check(format!(
        "modem_id: 1\ndriver {{ driver_type: DRIVER_UDP udp {{ local {{ port: 50001 }} }} }}\n\
         mac {{ type: MAC_FIXED_DECENTRALIZED {goby3_slot} }}\n"
    ));
    assert_eq!(code, Some(2), "{text}: {err}");
    assert!(
        err.contains("mac.slot[0].type: DRIVER_SPECIFIC slots are the Micro-Modem driver's")
            && err.contains("mac.slot[1].type"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_refuses_options_nested_too_deep_without_crashing() {
    let dir = scratch("command", "gobyd-deep");
    let depth = 100_000;
    let mut text = String::from(
        "syntax = \"proto2\";\nimport \"google/protobuf/descriptor.proto\";\n\
         import \"dccl/option_extensions.proto\";\npackage deep;\n\
         message R { optional R r = 1; }\n\
         extend google.protobuf.MessageOptions { optional R rr = 50000; }\n\
         message M {\n  option (dccl.msg) = { id: 2 max_bytes: 8 codec_version: 4 };\n  option (rr) = { ",
    );
    text.push_str(&"r { ".repeat(depth));
    text.push_str(&"} ".repeat(depth));
    text.push_str("};\n  optional int32 x = 1 [(dccl.field) = { min: 0 max: 10 }];\n}\n");
    let proto = dir.join("deep.proto");
    std::fs::write(&proto, text).unwrap();
    let config = dir.join("deep.pb.txt");
    std::fs::write(
        &config,
        format!(
            "modem_id: 1\ndccl {{ proto_file: \"{}\" }}\n",
            proto.to_str().unwrap()
        ),
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", config.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr_text(&out));
    let err = stderr_text(&out);
    assert!(
        err.starts_with("gobyd: error: ") && err.contains("deep.proto"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A type coded with an arithmetic model, the models' file and a
/// configuration loading both; `adaptive`: whether the model is.
fn arithmetic_config(dir: &std::path::Path, adaptive: bool) -> PathBuf {
    let proto = dir.join("counts.proto");
    std::fs::write(
        &proto,
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
import "dccl/arithmetic/protobuf/arithmetic_extensions.proto";
package arith;
message Inner {
  repeated int32 d = 1 [(dccl.field) = { codec: "dccl.arithmetic" max_repeat: 6 [arithmetic] { model: "counts" } }];
}
message Counts {
  option (dccl.msg) = { id: 41 max_bytes: 64 codec_version: 4 };
  required bool flag = 1;
  optional Inner inner = 2;
}
"#,
    )
    .unwrap();
    let models = dir.join("models.txt");
    std::fs::write(
        &models,
        format!(
            "name: \"counts\" value_bound: 0 frequency: 1 value_bound: 1 frequency: 1 value_bound: 2 frequency: 1 value_bound: 3 eof_frequency: 1 out_of_range_frequency: 1{}\n",
            if adaptive { " is_adaptive: true" } else { "" }
        ),
    )
    .unwrap();
    let config = dir.join("arith.pb.txt");
    std::fs::write(
        &config,
        format!(
            "modem_id: 1\ndata_dir: \"{}\"\njson {{ tcp_bind: \"\" }}\ndccl {{ load_examples: false proto_file: \"{}\" arithmetic_model_file: \"{}\" }}\n",
            dir.join("data").display(),
            proto.display(),
            models.display()
        ),
    )
    .unwrap();
    config
}

#[test]
fn adaptive_arithmetic_models_are_refused_naming_message_field_and_model() {
    let dir = scratch("command", "gobyd-adaptive");
    let config = arithmetic_config(&dir, false);
    let out = gobyd(&["--check", "--config", config.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert!(stdout_text(&out).contains("arith.Counts"));

    let config = arithmetic_config(&dir, true);
    let expected = [
        "arith.Counts",
        "field inner.d",
        "adaptive arithmetic model \"counts\"",
        "encodes a message more than once",
    ];
    let out = gobyd(&["--check", "--config", config.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stderr_text(&out));
    let err = stderr_text(&out);
    for part in expected {
        assert!(err.contains(part), "{part} missing from {err}");
    }
    // The daemon does not start with it either.
    let out = assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(["--config", config.to_str().unwrap()])
        .timeout(std::time::Duration::from_secs(20))
        .output()
        .expect("gobyd runs");
    assert!(!out.status.success());
    let err = stderr_text(&out);
    for part in expected {
        assert!(err.contains(part), "{part} missing from {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn an_arithmetic_model_defined_twice_is_refused() {
    let dir = scratch("command", "gobyd-model-twice");
    let config = arithmetic_config(&dir, false);
    let models = dir.join("models.txt");
    let once = std::fs::read_to_string(&models).unwrap();
    // The same name again, with other frequencies.
    let again = once.replace("frequency: 1 value_bound: 1", "frequency: 5 value_bound: 1");
    std::fs::write(&models, format!("{once}{again}")).unwrap();
    let out = gobyd(&["--check", "--config", config.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stdout_text(&out));
    let err = stderr_text(&out);
    assert!(
        err.contains("models.txt") && err.contains("\"counts\" is defined twice"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// Settings that parse but cannot work, in files: `--check` refuses each
/// naming the field and where it is written, and the daemon refuses to
/// start with the same words.
#[test]
fn check_and_start_refuse_what_cannot_work_naming_field_and_place() {
    let port = SerialPort::open();
    let dir = scratch("command", "gobyd-limits");
    let path = dir.join("node.pb.txt");
    let file = path.display().to_string();
    for (text, expected) in [
        (
            "modem_id: 1\ndriver {\n  driver_type: DRIVER_WHOI_MICROMODEM\n  serial_port: \"/dev/ttyUSB0\"\n}\n\
             mac {\n  type: MAC_FIXED_DECENTRALIZED\n  slot { src: 1 rate: 2 slot_seconds: 1 }\n}\n",
            vec![format!(
                "{file}:8:25: mac.slot[0].slot_seconds: 1 s is too short for a rate-2 packet of 3 frames \
                 on the Micro-Modem (needs at least 4.2 s"
            )],
        ),
        (
            "modem_id: 1\nmac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 rate: 0 slot_seconds: 3 } }\n",
            vec![format!(
                "{file}:2:59: mac.slot[0].slot_seconds: 3 s is too short for a rate-0 packet of 1 frame \
                 on the simulator (needs at least 3.7 s"
            )],
        ),
        (
            "modem_id: 1\ndriver_cfg {\n  driver_type: DRIVER_UDP\n  [goby.acomms.udp.protobuf.config] {\n    \
             local { port: 70000 }\n    remote { modem_id: 2 ip: \"not-an-ip\" port: 50002 }\n  }\n}\n",
            vec![
                "2 settings cannot work:".to_string(),
                format!("{file}:5:13: driver.udp.local.port: 70000 is not a UDP port (0-65535)"),
                format!("{file}:6:26: driver.udp.remote[0].ip: \"not-an-ip\" is not an IP address"),
            ],
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_ACOUSTIC_SIMULATOR\n  simulator { node { modem_id: 1 } packet_loss: 1.5 }\n}\n",
            vec![format!(
                "{file}:3:36: driver.simulator.packet_loss: 1.5 is not a probability (0 to 1"
            )],
        ),
        (
            "modem_id: 1\ndriver { driver_type: DRIVER_WHOI_MICROMODEM serial_port: \"/dev/no-such-modem\" }\n",
            vec![format!(
                "{file}:2:46: driver.serial_port: \"/dev/no-such-modem\" does not exist"
            )],
        ),
    ] {
        std::fs::write(&path, port.with_port(text)).unwrap();
        // The JSON port off in both runs, as the start below: what the
        // check tells of this machine's ports is not the configuration's.
        let out = gobyd(&["--check", "--config", &file, "--json-tcp", ""]);
        assert_eq!(out.status.code(), Some(2), "{text}");
        let checked = stderr_text(&out);
        assert!(checked.starts_with("gobyd: error: configuration: "), "{checked}");
        for part in &expected {
            assert!(checked.contains(part.as_str()), "{part:?} missing from {checked}");
        }
        let data = dir.join("data");
        let out = assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
            .args(["--config", &file, "--json-tcp", "", "--data-dir"])
            .arg(&data)
            .env_remove("RUST_BACKTRACE")
            .env_remove("RUST_LOG")
            .timeout(std::time::Duration::from_secs(20))
            .output()
            .expect("gobyd runs");
        assert_eq!(out.status.code(), Some(2), "{text}");
        assert_eq!(stderr_text(&out), checked, "the start refuses it the same");
        assert!(!data.exists(), "refused before anything is set up");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn the_mqtt_broker_option_overrides_the_configuration_and_check_says_so() {
    let dir = scratch("command", "mqtt-broker");
    let with = dir.join("with-mqtt.pb.txt");
    std::fs::write(
        &with,
        "modem_id: 1\nmqtt { broker: \"10.9.9.9:1999\" topic_prefix: \"fleet\" }\n",
    )
    .unwrap();
    let without = dir.join("without-mqtt.pb.txt");
    std::fs::write(&without, "modem_id: 1\n").unwrap();
    let (with, without) = (with.to_str().unwrap(), without.to_str().unwrap());
    let check = |args: &[&str]| {
        let mut all = vec!["--check"];
        all.extend_from_slice(args);
        let out = gobyd(&all);
        assert!(out.status.success(), "{args:?}: {}", stderr_text(&out));
        let stdout = stdout_text(&out);
        let mut lines = stdout.lines();
        assert!(
            lines.next().unwrap().starts_with("configuration is valid;"),
            "{stdout}"
        );
        lines.next().unwrap_or("").to_string()
    };
    assert_eq!(
        check(&["--config", with]),
        "MQTT broker: 10.9.9.9:1999 (from the configuration)"
    );
    assert_eq!(
        check(&["--config", with, "--mqtt-broker", "127.0.0.1"]),
        "MQTT broker: 127.0.0.1:1883 (from --mqtt-broker)"
    );
    assert_eq!(
        check(&["--config", with, "--mqtt-broker", "[::1]:1884"]),
        "MQTT broker: [::1]:1884 (from --mqtt-broker)"
    );
    // A configuration without an mqtt section gets one; an empty value
    // turns the bridge off; no bridge, no line.
    assert_eq!(
        check(&["--config", without, "--mqtt-broker", "broker.local:1999"]),
        "MQTT broker: broker.local:1999 (from --mqtt-broker)"
    );
    assert_eq!(
        check(&["--config", with, "--mqtt-broker", ""]),
        "MQTT bridge: none (from --mqtt-broker)"
    );
    assert_eq!(check(&["--config", without]), "");
    // A bad value is the option's error, not the file's.
    let out = gobyd(&["--check", "--config", with, "--mqtt-broker", "broker:port"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(
        err.contains("--mqtt-broker \"broker:port\" is not HOST[:PORT]") && !err.contains(with),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The installing commands of `docs/README.md` that call `gobyd`, as
/// written, for a user whose `gobyd` is in `~/.cargo/bin`: they work in a
/// fresh home, and `man` finds the page without a MANPATH.
#[test]
fn the_documented_installing_commands_work_in_a_fresh_home() {
    let home = scratch("command", "install-home");
    let bin = home.join(".cargo/bin");
    std::fs::create_dir_all(&bin).unwrap();
    std::os::unix::fs::symlink(env!("CARGO_BIN_EXE_gobyd"), bin.join("gobyd")).unwrap();
    let path = format!("{}:/usr/local/bin:/usr/bin:/bin", bin.display());
    let script = guide_check::installing_commands("gobyd");
    assert!(script.contains("gobyd --man "), "{script}");
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
        stdout_text(&out),
        stderr_text(&out)
    );
    for written in [
        ".local/share/bash-completion/completions/gobyd",
        ".cargo/share/man/man1/gobyd.1",
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
            .args(["-w", "gobyd"])
            .env_clear()
            .env("HOME", &home)
            .env("PATH", &path)
            .output()
            .unwrap();
        assert!(out.status.success(), "{}", stderr_text(&out));
        let page = home.join(".cargo/share/man/man1/gobyd.1");
        assert!(
            stdout_text(&out).contains(&page.display().to_string()),
            "man -w: {}",
            stdout_text(&out)
        );
    } else {
        eprintln!("man is not installed: where man finds the page is not checked");
    }
}

#[test]
fn gobyd_prints_completions_and_writes_its_man_page() {
    let out = gobyd(&["--completions", "bash"]);
    assert!(out.status.success(), "{}", stderr_text(&out));
    let bash = stdout_text(&out);
    for word in ["gobyd", "--mqtt-broker", "--moos-file", "--check", "--man"] {
        assert!(bash.contains(word), "{word} missing from the bash script");
    }
    for shell in ["zsh", "fish", "elvish", "powershell"] {
        let out = gobyd(&["--completions", shell]);
        assert!(out.status.success(), "{shell}: {}", stderr_text(&out));
        assert!(stdout_text(&out).contains("mqtt-broker"), "{shell}");
    }
    let out = gobyd(&["--completions", "tcsh"]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(
        err.contains("invalid value 'tcsh'") && err.contains("bash, elvish, fish, powershell, zsh"),
        "{err}"
    );

    let dir = scratch("command", "man").join("man1");
    let out = gobyd(&["--man", dir.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr_text(&out));
    let page = dir.join("gobyd.1");
    assert_eq!(stdout_text(&out).trim(), page.display().to_string());
    let text = std::fs::read_to_string(&page).unwrap();
    assert!(text.contains(".TH gobyd 1"), "{text}");
    for option in [
        r"\-\-mqtt\-broker",
        r"\-\-check",
        r"\-\-moos\-file",
        r"\-\-completions",
    ] {
        assert!(text.contains(option), "{option} missing from gobyd.1");
    }
    let out = gobyd(&["--man", "/dev/null/man1"]);
    assert_eq!(out.status.code(), Some(2));
    assert!(
        stderr_text(&out).contains("cannot create the directory /dev/null/man1"),
        "{}",
        stderr_text(&out)
    );
}

#[test]
fn check_lists_every_refused_queue_entry_at_its_place() {
    let dir = scratch("command", "gobyd-queue-entries");
    let proto = dir.join("kinds.proto");
    std::fs::write(
        &proto,
        "syntax = \"proto2\";\nimport \"dccl/option_extensions.proto\";\npackage test;\n\
         message Quiet {\n  option (dccl.msg) = { id: 120 max_bytes: 32 codec_version: 4 omit_id: true };\n\
           required bool on = 1;\n}\n\
         message Report {\n  option (dccl.msg) = { id: 121 max_bytes: 32 codec_version: 4 };\n\
           required bool on = 1;\n}\n",
    )
    .unwrap();
    let path = dir.join("node.pb.txt");
    std::fs::write(
        &path,
        format!(
            "modem_id: 1\ndccl {{ proto_file: \"{}\" load_examples: false }}\nqueue {{\n  \
             message_entry {{ protobuf_name: \"test.Reprot\" }}\n  \
             message_entry {{ protobuf_name: \"test.Quiet\" }}\n}}\n",
            proto.display()
        ),
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    for part in [
        "node.pb.txt:4:",
        "queue.message_entry[0].protobuf_name: \"test.Reprot\" is not a DCCL type of the loaded .proto files (loaded: ",
        "test.Report",
        "node.pb.txt:5:",
        "queue.message_entry[1].protobuf_name: its (dccl.msg) has omit_id: true",
    ] {
        assert!(err.contains(part), "{part:?} in {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_places_the_mqtt_sections_problems() {
    let dir = scratch("command", "gobyd-mqtt-places");
    let path = dir.join("node.pb.txt");
    std::fs::write(
        &path,
        "modem_id: 1\nmqtt {\n  broker: \"127.0.0.1:1883\"\n  qos: 2\n}\n",
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(
        err.contains("node.pb.txt:4:3: mqtt.qos: 2 is not supported: use 0 or 1"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[cfg(unix)]
#[test]
fn check_warns_of_a_passphrase_file_others_can_read() {
    use std::os::unix::fs::PermissionsExt;
    let dir = scratch("command", "gobyd-passphrase-mode");
    let secret = dir.join("pass.txt");
    std::fs::write(&secret, "secret\n").unwrap();
    std::fs::set_permissions(&secret, std::fs::Permissions::from_mode(0o644)).unwrap();
    let path = dir.join("node.pb.txt");
    std::fs::write(
        &path,
        format!(
            "modem_id: 1\ndccl {{ passphrase_file: \"{}\" }}\n",
            secret.display()
        ),
    )
    .unwrap();
    let check = || gobyd(&["--check", "--config", path.to_str().unwrap()]);
    let out = check();
    assert!(out.status.success(), "{}", stderr_text(&out));
    let err = stderr_text(&out);
    assert_eq!(
        err.matches("can be read by other users (chmod 600 it)")
            .count(),
        1,
        "{err}"
    );
    std::fs::set_permissions(&secret, std::fs::Permissions::from_mode(0o600)).unwrap();
    let out = check();
    assert!(out.status.success(), "{}", stderr_text(&out));
    assert!(
        !stderr_text(&out).contains("other users"),
        "{}",
        stderr_text(&out)
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--check` tells the EvoLogics S2C driver's frame limits, refuses a
/// message larger than its largest frame and every setting it cannot
/// work with.
#[test]
fn check_knows_the_evologics_limits() {
    let dir = scratch("command", "gobyd-evologics");
    let path = dir.join("evologics.pb.txt");
    let driver = |extra: &str| {
        let server = if extra.contains("tcp_server") {
            ""
        } else {
            "tcp_server: \"127.0.0.1\""
        };
        format!(
            "modem_id: 1\ndriver {{ driver_name: \"EVOLOGICS_S2C\" connection_type: CONNECTION_TCP_AS_CLIENT \
             {server} {extra} }}\n"
        )
    };
    std::fs::write(&path, driver("")).unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert_eq!(out.status.code(), Some(0), "{text}{}", stderr_text(&out));
    assert!(
        text.contains("driver EVOLOGICS_S2C: one frame per transmission; up to 64 bytes as an instant message (AT*SENDIM), up to 1024 bytes as burst data (AT*SEND) to one node"),
        "{text}"
    );
    // With the network layer on, the fragments' size: an instant
    // message's frame, which a slot of `dest: -1` offers.
    std::fs::write(
        &path,
        driver("")
            + "mac { type: MAC_FIXED_DECENTRALIZED slot { src: 1 dest: -1 slot_seconds: 10 } }\n\
               network { }\n",
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    let text = String::from_utf8_lossy(&out.stdout).into_owned();
    assert_eq!(out.status.code(), Some(0), "{text}{}", stderr_text(&out));
    assert!(
        text.contains(
            "network: a message larger than a frame, or a file, goes in fragments of 58 bytes \
             of data (64 with their header: the smallest frame of this node's slots)"
        ),
        "{text}"
    );
    std::fs::write(
        &path,
        driver("evologics { im_max_bytes: 16 burst_max_bytes: 0 }"),
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    let err = stderr_text(&out);
    assert_eq!(out.status.code(), Some(2), "{err}");
    assert!(
        err.contains("more than the 16 bytes of the driver's largest frame"),
        "{err}"
    );
    for (extra, expected) in [
        (
            "tcp_server: \"\"",
            "driver.tcp_server: required for the EvoLogics driver over TCP",
        ),
        (
            "evologics { address: 255 }",
            "driver.evologics.address: 255 is not an S2C address",
        ),
        (
            "evologics { source_level: 5 }",
            "driver.evologics.source_level: 5 is not a source level",
        ),
        (
            "evologics { im_max_bytes: 65 }",
            "driver.evologics.im_max_bytes: 65 is not an instant-message size",
        ),
        (
            "evologics { burst_max_bytes: 5000 }",
            "driver.evologics.burst_max_bytes: 5000 bytes is more than",
        ),
        (
            "tcp_port: 70000",
            "driver.tcp_port: 70000 is not a TCP port",
        ),
    ] {
        std::fs::write(&path, driver(extra)).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        let err = stderr_text(&out);
        assert_eq!(out.status.code(), Some(2), "{extra}: {err}");
        assert!(err.contains(expected), "{extra}: {err}");
    }
    std::fs::write(
        &path,
        "modem_id: 1\ndriver { driver_name: \"EVOLOGICS_S3C\" }\n",
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    let err = stderr_text(&out);
    // The drivers named by driver_name are listed; EVOLOGICS_S2C among them.
    assert!(
        err.contains("no driver named \"EVOLOGICS_S3C\" is built in (driver_name ")
            && err.contains("\"EVOLOGICS_S2C\""),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `--check` tells what a type's dynamic conditions cannot do as written,
/// naming the message, the field and the script: a name that is no field
/// of the message (the script sees nil, as libdccl's Lua), a condition
/// codec version 2 ignores, a condition reading a field decoded after it.
#[test]
fn check_warns_about_conditions_that_cannot_do_what_they_say() {
    let dir = scratch("command", "gobyd-conditions");
    let proto = dir.join("cond.proto");
    std::fs::write(
        &proto,
        r#"syntax = "proto2";
import "dccl/option_extensions.proto";
package cond;
message Typo {
  option (dccl.msg) = { id: 5 max_bytes: 32 codec_version: 4 };
  required int32 mode = 1 [(dccl.field) = { min: 0 max: 200 }];
  optional int32 a = 2 [(dccl.field) = { min: 0 max: 10
      dynamic_conditions { omit_if: "this.moode == 1" } }];
  optional int32 b = 3 [(dccl.field) = { min: 0 max: 10
      dynamic_conditions { max: "this.c" } }];
  optional int32 c = 4 [(dccl.field) = { min: 0 max: 10 }];
}
message Old {
  option (dccl.msg) = { id: 6 max_bytes: 32 codec_version: 2 };
  required int32 mode = 1 [(dccl.field) = { min: 0 max: 200 }];
  optional int32 a = 2 [(dccl.field) = { min: 0 max: 10
      dynamic_conditions { only_if: "this.mode == 1" } }];
}
"#,
    )
    .unwrap();
    let config = dir.join("cond.pb.txt");
    std::fs::write(
        &config,
        format!(
            "modem_id: 1\ndccl {{ proto_file: \"{}\" }}\n",
            proto.to_str().unwrap()
        ),
    )
    .unwrap();
    let out = gobyd(&["--check", "--config", config.to_str().unwrap()]);
    let err = stderr_text(&out);
    assert!(out.status.success(), "{err}");
    for warning in [
        "gobyd: warning: cond.Typo.a: dynamic_conditions.omit_if \"this.moode == 1\" reads this.moode: cond.Typo has no field moode (the script sees nil)",
        "gobyd: warning: cond.Typo.b: dynamic_conditions.max \"this.c\" reads this.c, which is decoded after b:",
        "gobyd: warning: cond.Old.a: dynamic_conditions.only_if \"this.mode == 1\" is ignored: codec version 2",
    ] {
        assert!(err.contains(warning), "{warning}\n{err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A configuration file that configures nothing (empty, or blank lines
/// and comments only: a copy that failed, the wrong file) is refused by
/// `--check` and by the start, the error naming the file and the defaults
/// it would have run on, and how to run on them on purpose.
#[test]
fn an_empty_configuration_file_is_refused_naming_the_defaults() {
    let dir = scratch("command", "gobyd-empty");
    for (name, text) in [
        ("empty.pb.txt", ""),
        (
            "comments.pb.txt",
            "\n  # all of it commented out\n# modem_id: 2\n\n",
        ),
    ] {
        let path = dir.join(name);
        std::fs::write(&path, text).unwrap();
        let path = path.to_str().unwrap();
        let check = gobyd(&["--check", "--config", path]);
        // The start is bounded: before this refusal it ran until stopped.
        let data = dir.join("data");
        let start = assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
            .args(["--config", path, "--json-tcp", "127.0.0.1:0", "--data-dir"])
            .arg(&data)
            .env_remove("RUST_BACKTRACE")
            .timeout(std::time::Duration::from_secs(30))
            .output()
            .expect("gobyd runs");
        for (what, out) in [("--check", &check), ("start", &start)] {
            let err = stderr_text(out);
            assert_eq!(out.status.code(), Some(2), "{what} {name}: {err}");
            assert!(stdout_text(out).is_empty(), "{what} {name}");
            for part in [
                &format!("gobyd: error: configuration: {path} configures nothing"),
                "node 1",
                "the in-process acoustic simulator",
                "data directory ./gobyd-data",
                "JSON interface on 127.0.0.1:11145",
                "without --config",
                "gobyd --example-config",
            ] {
                assert!(err.contains(part), "{what} {name}: {part:?} in {err}");
            }
        }
        assert!(!data.exists(), "the start made its data directory");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// A configuration of the acoustic simulator over modelled water with
/// `summer_env` as its BELLHOP environment.
fn modelled_water_config(dir: &std::path::Path, summer_env: &std::path::Path) -> PathBuf {
    let path = dir.join("water.pb.txt");
    std::fs::write(
        &path,
        format!(
            r#"modem_id: 1
driver {{
  driver_type: DRIVER_ACOUSTIC_SIMULATOR
  simulator {{
    node {{ modem_id: 1 x: 0 z: -30 }}
    node {{ modem_id: 2 x: 3000 z: -45 }}
    acoustic_channel {{ env: "{}" source_level_db: 190 }}
  }}
}}
mac {{
  type: MAC_FIXED_DECENTRALIZED
  slot {{ src: 1 slot_seconds: 10 }}
  slot {{ src: 2 slot_seconds: 10 }}
}}
"#,
            summer_env.display()
        ),
    )
    .unwrap();
    path
}

#[test]
fn check_accepts_the_simulator_over_modelled_water_and_names_a_bad_env_by_line() {
    let dir = scratch("command", "gobyd-water");
    let shipped = workspace_dir().join("channel/tests/data/bellhop/summer.env");
    let good = modelled_water_config(&dir, &shipped);
    let out = gobyd(&["--check", "--config", good.to_str().unwrap()]);
    assert!(out.status.success(), "{}", stderr_text(&out));

    // The same file with its sound speeds cut off: refused by file and line.
    let text = std::fs::read_to_string(&shipped).unwrap();
    let cut: Vec<&str> = text.lines().take(9).collect();
    let bad_env = dir.join("bad.env");
    std::fs::write(&bad_env, cut.join("\n") + "\n").unwrap();
    let bad = modelled_water_config(&dir, &bad_env);
    let out = gobyd(&["--check", "--config", bad.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2), "{}", stdout_text(&out));
    let err = stderr_text(&out);
    assert!(
        err.contains("simulator.acoustic_channel.env") && err.contains("bad.env:"),
        "{err}"
    );

    // A file that is not there.
    let missing = modelled_water_config(&dir, &dir.join("none.env"));
    let out = gobyd(&["--check", "--config", missing.to_str().unwrap()]);
    assert_eq!(out.status.code(), Some(2));
    let err = stderr_text(&out);
    assert!(err.contains("none.env"), "{err}");
    std::fs::remove_dir_all(&dir).unwrap();
}

/// An Iridium link without `duplicate_window_seconds`: `--check` says that
/// a copy held at the gateway past the window (the longest ttl) is
/// delivered again, naming the driver; not once the window is set.
#[test]
fn an_iridium_link_without_a_duplicate_window_is_told_what_the_gateway_can_hold() {
    let dir = scratch("command", "gateway-window");
    // The shipped shore station, without the window it sets.
    let shipped =
        std::fs::read_to_string(workspace_dir().join("gobyd/config/iridium-shore.pb.txt")).unwrap();
    let shipped: String = shipped
        .lines()
        .filter(|l| !l.starts_with("duplicate_window_seconds"))
        .map(|l| format!("{l}\n"))
        .collect();
    let path = dir.join("shore.pb.txt");
    let check = |text: &str| {
        std::fs::write(&path, text).unwrap();
        let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
        (out.status.code(), stderr_text(&out))
    };
    let (code, err) = check(&shipped);
    assert_eq!(code, Some(0), "{err}");
    assert!(
        err.contains("shore.pb.txt:10:3: an Iridium link: the gateway holds copies")
            && err.contains("(unset: the longest ttl, 1800 s)")
            && err.contains("set duplicate_window_seconds to the ttl and the longest time"),
        "{err}"
    );
    let (code, err) = check(&format!("duplicate_window_seconds: 14400\n{shipped}"));
    assert_eq!(code, Some(0), "{err}");
    assert!(!err.contains("an Iridium link: the gateway holds"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

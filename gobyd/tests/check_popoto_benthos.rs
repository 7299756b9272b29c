//! `gobyd --check` of the Popoto and Benthos ATM-900 drivers: their
//! configuration as Goby3's pAcommsHandler writes it (the driver types and
//! the `[goby.acomms.popoto.protobuf.config]` /
//! `[goby.acomms.benthos.protobuf.config]` extensions), the frame limits
//! per rate it tells, a message type larger than the driver's frame
//! refused, and bad settings refused naming their field.

mod support;

use std::process::Output;

use support::daemon::scratch;

fn gobyd(args: &[&str]) -> Output {
    assert_cmd::Command::new(env!("CARGO_BIN_EXE_gobyd"))
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .expect("gobyd runs")
}

fn stderr_text(out: &Output) -> String {
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn check(path: &std::path::Path, text: &str) -> (Option<i32>, String, String) {
    std::fs::write(path, text).unwrap();
    let out = gobyd(&["--check", "--config", path.to_str().unwrap()]);
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        stderr_text(&out),
    )
}

#[test]
fn check_knows_the_popoto_limits() {
    let dir = scratch("check", "popoto");
    let path = dir.join("popoto.pb.txt");
    let config = |extra: &str| {
        format!(
            "modem_id: 1\ndriver_cfg {{\n  driver_type: DRIVER_POPOTO\n  connection_type: CONNECTION_TCP_AS_CLIENT\n  \
             tcp_server: \"127.0.0.1\"\n  [goby.acomms.popoto.protobuf.config] {{ payload_mode: 1 modem_power: 10 {extra} }}\n}}\n"
        )
    };
    let (code, out, err) = check(&path, &config(""));
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains(
            "driver DRIVER_POPOTO: one frame per transmission of up to 255 bytes at every rate"
        ),
        "{out}"
    );
    for rate in [
        "rate 0 payload mode 0 80 bit/s",
        "rate 1 payload mode 4 640 bit/s",
        "rate 4 payload mode 1 5120 bit/s",
        "rate 5 payload mode 5 10240 bit/s",
    ] {
        assert!(out.contains(rate), "{rate}: {out}");
    }
    // A type larger than the frame would never go.
    let (code, _, err) = check(&path, &config("max_frame_bytes: 8"));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("more than the 8 bytes of the driver's largest frame"),
        "{err}"
    );
    // With the network layer on, it goes to one node in fragments of
    // the frame's size.
    let (code, out, err) = check(
        &path,
        &format!("{}network {{ }}\n", config("max_frame_bytes: 8")),
    );
    assert_eq!(code, Some(0), "{out}{err}");
    for (extra, expected) in [
        (
            "payload_mode: 7",
            "driver.popoto.payload_mode: 7 is not a payload mode",
        ),
        (
            "max_frame_bytes: 1023",
            "driver.popoto.max_frame_bytes: 1023 is not a frame size",
        ),
        (
            "setting: \"RNG_TA_DelayMs\"",
            "driver.popoto.setting[0]: \"RNG_TA_DelayMs\" is not \"Name value\"",
        ),
    ] {
        let text = config(extra).replace("payload_mode: 1 ", "");
        let (code, _, err) = check(&path, &text);
        assert_eq!(code, Some(2), "{extra}: {err}");
        assert!(err.contains(expected), "{extra}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn check_knows_the_benthos_limits() {
    let dir = scratch("check", "benthos");
    let path = dir.join("benthos.pb.txt");
    let config = |extra: &str| {
        format!(
            "modem_id: 2\ndriver_cfg {{\n  driver_type: DRIVER_BENTHOS_ATM900\n  connection_type: CONNECTION_TCP_AS_CLIENT\n  \
             tcp_server: \"127.0.0.1\" tcp_port: 4001\n  [goby.acomms.benthos.protobuf.config] {{\n    \
             config: \"@AcRspTmOut=10.0\"\n    {extra}\n  }}\n}}\n"
        )
    };
    let (code, out, err) = check(&path, &config(""));
    assert_eq!(code, Some(0), "{out}{err}");
    assert!(
        out.contains("driver DRIVER_BENTHOS_ATM900: up to 8 frames per transmission"),
        "{out}"
    );
    assert!(
        out.contains("of up to 64 bytes each at every rate"),
        "{out}"
    );
    assert!(out.contains("2 140 bit/s"), "{out}");
    let (code, _, err) = check(&path, &config("max_frame_size: 8"));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("more than the 8 bytes of the driver's largest frame"),
        "{err}"
    );
    for (extra, expected) in [
        (
            "max_frame_size: 5000",
            "driver.benthos.max_frame_size: 5000 is not a frame size",
        ),
        (
            "config: \"@=1\"",
            "driver.benthos.config[1]: \"@=1\": \"\" is not a setting name",
        ),
        (
            "ack_rate: 14",
            "driver.benthos.ack_rate: 14 is not an @TxRate",
        ),
    ] {
        let (code, _, err) = check(&path, &config(extra));
        assert_eq!(code, Some(2), "{extra}: {err}");
        assert!(err.contains(expected), "{extra}: {err}");
    }
    let (code, _, err) = check(
        &path,
        "modem_id: 2\ndriver { driver_type: DRIVER_BENTHOS_ATM900 connection_type: CONNECTION_TCP_AS_CLIENT tcp_server: \"x\" }\n",
    );
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains("driver.tcp_port: required for the Benthos driver"),
        "{err}"
    );
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_benthos_ping_slot_is_checked_as_the_driver_runs_it() {
    let dir = scratch("check", "benthos-ping");
    let path = dir.join("benthos-ping.pb.txt");
    let config = |slot: &str| {
        format!(
            "modem_id: 1\ndriver_cfg {{ driver_type: DRIVER_BENTHOS_ATM900 connection_type: CONNECTION_TCP_AS_CLIENT \
             tcp_server: \"127.0.0.1\" tcp_port: 4001 }}\n\
             mac_cfg {{ type: MAC_FIXED_DECENTRALIZED\n  slot {{ src: 1 rate: 5 slot_seconds: 8 }}\n  {slot}\n}}\n"
        )
    };
    // Goby3's ranging slot: a two-way ping of node 2.
    let ping = "slot { src: 1 dest: 2 type: DRIVER_SPECIFIC slot_seconds: 8 \
                [goby.acomms.benthos.protobuf.transmission] { type: BENTHOS_TWO_WAY_PING } }";
    let (code, out, err) = check(&path, &config(ping));
    assert_eq!(code, Some(0), "{out}{err}");
    for (slot, expected) in [
        (
            "slot { src: 1 dest: 2 type: DRIVER_SPECIFIC slot_seconds: 8 }",
            "mac.slot[1].benthos.type: a DRIVER_SPECIFIC slot of the Benthos ATM-900 driver is a two-way ping",
        ),
        (
            "slot { src: 1 type: DRIVER_SPECIFIC slot_seconds: 8 \
             [goby.acomms.benthos.protobuf.transmission] { type: BENTHOS_TWO_WAY_PING } }",
            "mac.slot[1].dest: a two-way ping needs the node to range in dest",
        ),
    ] {
        let (code, _, err) = check(&path, &config(slot));
        assert_eq!(code, Some(2), "{slot}: {err}");
        assert!(err.contains(expected), "{slot}: {err}");
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

#[test]
fn a_type_of_several_links_must_fit_their_frames_with_its_identity() {
    let dir = std::env::temp_dir().join(format!("gobyd-check-links-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("links.cfg");
    // goby.example.Command encodes to up to 25 bytes; its trailer alone
    // takes 4 more.
    let link = |name: &str, port: u16, bytes: u32| {
        format!(
            "link {{\n  name: \"{name}\"\n  driver {{ driver_type: DRIVER_POPOTO connection_type: CONNECTION_TCP_AS_CLIENT \
             tcp_server: \"127.0.0.1\" tcp_port: {port} popoto {{ max_frame_bytes: {bytes} }} }}\n  \
             mac {{ type: MAC_FIXED_DECENTRALIZED slot {{ src: 1 dest: -1 rate: 1 slot_seconds: 10 }} }}\n}}\n"
        )
    };
    let two = |bytes: u32, extra: &str| {
        format!(
            "modem_id: 1\ndata_dir: \"{}\"\n{}{}{extra}",
            dir.join("data").display(),
            link("a", 17000, bytes),
            link("b", 17001, bytes)
        )
    };
    let (code, _, err) = check(&path, &two(27, ""));
    assert_eq!(code, Some(2), "{err}");
    assert!(
        err.contains(
            "goby.example.Command encodes to up to 25 bytes (with the identity trailer of 4 bytes \
             a type of several links carries, 29 bytes), more than the largest frame of every link"
        ),
        "{err}"
    );
    let (code, out, err) = check(&path, &two(29, ""));
    assert_eq!(code, Some(0), "{out}{err}");
    // Frames without identity: the message alone must fit.
    let (code, out, err) = check(&path, &two(27, "queue { message_identity: false }\n"));
    assert_eq!(code, Some(0), "{out}{err}");
    let _ = std::fs::remove_dir_all(&dir);
}

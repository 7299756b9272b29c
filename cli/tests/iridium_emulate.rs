//! `goby modem emulate-iridium`: the printed pseudo-terminal speaks the
//! 9603's AT commands, the gateway takes a DirectIP MT message and rings the
//! transceiver, and a session hands the message over and delivers the MO
//! message to the DirectIP listener given.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::{TcpListener, TcpStream};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use modemdriver::iridium::at;
use modemdriver::iridium::directip::{self, MoMessage, MtConfirmation, MtMessage};

const IMEI: &str = "300234010753371";

struct Emulator(Child);

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Reads from the pseudo-terminal until `wanted` has come (or panics after 10 s).
fn read_until(pty: &mut std::fs::File, seen: &mut Vec<u8>, wanted: &[u8]) {
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut buf = [0u8; 256];
    while !seen.windows(wanted.len()).any(|w| w == wanted) {
        assert!(
            Instant::now() < deadline,
            "no {:?} in {:?}",
            String::from_utf8_lossy(wanted),
            String::from_utf8_lossy(seen)
        );
        match pty.read(&mut buf) {
            Ok(n) if n > 0 => seen.extend_from_slice(&buf[..n]),
            _ => std::thread::sleep(Duration::from_millis(20)),
        }
    }
}

#[test]
fn the_emulated_9603_and_gateway_carry_messages_both_ways() {
    let shore = TcpListener::bind("127.0.0.1:0").unwrap();
    let mo = shore.local_addr().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["modem", "emulate-iridium", "--imei", IMEI])
        .args([
            "--mo-directip",
            &mo.to_string(),
            "--mt-directip",
            "127.0.0.1:0",
        ])
        .args(["--session-seconds", "0.2", "--duration", "30"])
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("goby runs");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let stderr = child.stderr.take().unwrap();
    let (told_tx, told_rx) = std::sync::mpsc::channel::<String>();
    std::thread::spawn(move || {
        for line in BufReader::new(stderr).lines().map_while(Result::ok) {
            let _ = told_tx.send(line);
        }
    });
    let _emulator = Emulator(child);
    let first = lines.next().unwrap().unwrap();
    let path = first
        .strip_prefix(&format!("transceiver {IMEI}: "))
        .unwrap_or_else(|| panic!("{first}"))
        .to_string();
    let second = lines.next().unwrap().unwrap();
    let mt_addr = second.rsplit("MT on ").next().unwrap().trim().to_string();
    assert!(
        second.starts_with(&format!("gateway: MO to {mo}")),
        "{second}"
    );

    let mut pty = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&path)
        .unwrap();
    // Raw bytes on the terminal, as a serial driver sets it.
    let status = Command::new("stty")
        .args(["-F", &path, "raw", "-echo"])
        .status()
        .unwrap();
    assert!(status.success());
    let mut seen = Vec::new();
    for (command, answer) in [
        (&b"ATE0\r"[..], &b"OK\r\n"[..]),
        (b"AT+SBDMTA=1\r", b"OK\r\n"),
        (b"AT+CGSN\r", IMEI.as_bytes()),
    ] {
        pty.write_all(command).unwrap();
        read_until(&mut pty, &mut seen, answer);
    }

    // An MT message, confirmed at its place in the queue, then a ring alert.
    let mut s = TcpStream::connect(&mt_addr).unwrap();
    s.write_all(
        &MtMessage {
            client_id: 9,
            imei: IMEI.into(),
            disposition_flags: 0,
            payload: Some(b"to the vehicle".to_vec()),
        }
        .encode(),
    )
    .unwrap();
    let confirmation = MtConfirmation::decode(&read_directip(&mut s)).unwrap();
    assert_eq!((confirmation.client_id, confirmation.status), (9, 1));
    read_until(&mut pty, &mut seen, b"SBDRING\r\n");

    // An MO message in the session that answers the ring.
    let mo_message = b"to the shore";
    pty.write_all(format!("AT+SBDWB={}\r", mo_message.len()).as_bytes())
        .unwrap();
    read_until(&mut pty, &mut seen, b"READY\r\n");
    let mut with_sum = mo_message.to_vec();
    with_sum.extend_from_slice(&at::checksum(mo_message).to_be_bytes());
    pty.write_all(&with_sum).unwrap();
    read_until(&mut pty, &mut seen, b"0\r\n\r\nOK\r\n");
    pty.write_all(b"AT+SBDIXA\r").unwrap();
    read_until(&mut pty, &mut seen, b"+SBDIX: 0, 0, 1, 1, 14, 0\r\n");
    seen.clear();
    pty.write_all(b"AT+SBDRB\r").unwrap();
    read_until(&mut pty, &mut seen, b"OK\r\n");
    assert_eq!(&seen[..2], &[0, 14]);
    assert_eq!(&seen[2..16], b"to the vehicle");

    let (mut conn, _) = shore.accept().unwrap();
    let bytes = read_directip(&mut conn);
    let mo = MoMessage::decode(&bytes).unwrap();
    assert_eq!(mo.header.imei, IMEI);
    assert_eq!(mo.payload.as_deref(), Some(&mo_message[..]));

    // What happened, told on standard error.
    let mut told = String::new();
    let deadline = Instant::now() + Duration::from_secs(10);
    while !(told.contains("ring alert") && told.contains("MT message(s) queued")) {
        let left = deadline.saturating_duration_since(Instant::now());
        match told_rx.recv_timeout(left) {
            Ok(line) => told += &format!("{line}\n"),
            Err(_) => panic!("not told: {told}"),
        }
    }
}

/// Reads one DirectIP message (pre-header, then the length it gives).
fn read_directip(stream: &mut TcpStream) -> Vec<u8> {
    let mut pre = [0u8; directip::PRE_HEADER_BYTES];
    stream.read_exact(&mut pre).unwrap();
    let len = directip::message_length(&pre).unwrap();
    let mut out = pre.to_vec();
    out.resize(len, 0);
    stream
        .read_exact(&mut out[directip::PRE_HEADER_BYTES..])
        .unwrap();
    out
}

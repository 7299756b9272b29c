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

/// Reads an HTTP/1.1 message (head, then `Content-Length` bytes of body)
/// from `stream`: the head and the body.
fn read_http(stream: &mut TcpStream) -> (String, Vec<u8>) {
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        if let Some(end) = got.windows(4).position(|w| w == b"\r\n\r\n") {
            let head = String::from_utf8_lossy(&got[..end]).to_string();
            let length = head
                .lines()
                .find_map(|l| {
                    let (k, v) = l.split_once(':')?;
                    k.eq_ignore_ascii_case("content-length")
                        .then(|| v.trim().parse::<usize>().ok())?
                })
                .unwrap_or(0);
            if got.len() >= end + 4 + length {
                return (head, got[end + 4..end + 4 + length].to_vec());
            }
        }
        let n = stream.read(&mut buf).unwrap();
        assert!(
            n > 0,
            "connection closed: {:?}",
            String::from_utf8_lossy(&got)
        );
        got.extend_from_slice(&buf[..n]);
    }
}

/// POSTs `form` to the emulated service's MT endpoint: the body answered.
fn mt_post(addr: &str, path: &str, form: &str) -> String {
    let mut s = TcpStream::connect(addr).unwrap();
    write!(
        s,
        "POST {path} HTTP/1.1\r\nHost: {addr}\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{form}",
        form.len()
    )
    .unwrap();
    let (head, body) = read_http(&mut s);
    assert!(head.starts_with("HTTP/1.1 200"), "{head}");
    String::from_utf8(body).unwrap()
}

#[test]
fn the_emulated_rockblock_service_takes_mt_posts_and_posts_signed_mo_messages() {
    use emulators::iridium::rockblock::EMULATOR_TEST_PUBLIC_KEY_PEM;
    use modemdriver::iridium::rockblock::{JwtVerifier, MoPost};
    let webhook = TcpListener::bind("127.0.0.1:0").unwrap();
    let webhook_addr = webhook.local_addr().unwrap();
    let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["modem", "emulate-iridium", "--imei", IMEI])
        .args([
            "--mt-directip",
            "127.0.0.1:0",
            "--rockblock-mt",
            "127.0.0.1:0",
        ])
        .args([
            "--rockblock-webhook",
            &format!("http://{webhook_addr}/hook"),
        ])
        .args([
            "--rockblock-username",
            "fleet",
            "--rockblock-password",
            "pw",
        ])
        .args(["--session-seconds", "0.2", "--duration", "30"])
        .stdout(Stdio::piped())
        .stderr(Stdio::null())
        .spawn()
        .expect("goby runs");
    let mut lines = BufReader::new(child.stdout.take().unwrap()).lines();
    let _emulator = Emulator(child);
    let first = lines.next().unwrap().unwrap();
    let path = first
        .strip_prefix(&format!("transceiver {IMEI}: "))
        .unwrap_or_else(|| panic!("{first}"))
        .to_string();
    let second = lines.next().unwrap().unwrap();
    let prefix = format!("rockblock: MO to http://{webhook_addr}/hook, MT on http://");
    let mt = second
        .strip_prefix(&prefix)
        .unwrap_or_else(|| panic!("{second}"));
    let (mt_addr, mt_path) = mt.split_at(mt.find('/').unwrap());
    assert_eq!(mt_path, "/rockblock/MT");

    let mut pty = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&path)
        .unwrap();
    let status = Command::new("stty")
        .args(["-F", &path, "raw", "-echo"])
        .status()
        .unwrap();
    assert!(status.success());
    let mut seen = Vec::new();
    for (command, answer) in [
        (&b"ATE0\r"[..], &b"OK\r\n"[..]),
        (b"AT+SBDMTA=1\r", b"OK\r\n"),
    ] {
        pty.write_all(command).unwrap();
        read_until(&mut pty, &mut seen, answer);
    }

    // Wrong credentials, then an MT message queued and rung.
    let form = |password: &str| {
        format!(
            "imei={IMEI}&username=fleet&password={password}&data={}",
            hex_of(b"to the vehicle")
        )
    };
    assert_eq!(
        mt_post(mt_addr, mt_path, &form("wrong")),
        "FAILED,10,Invalid login credentials"
    );
    let ok = mt_post(mt_addr, mt_path, &form("pw"));
    assert!(ok.starts_with("OK,"), "{ok}");
    read_until(&mut pty, &mut seen, b"SBDRING\r\n");

    // An MO message in the session that answers the ring, posted to the
    // webhook with a JWT the committed public key verifies.
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
    assert_eq!(&seen[2..16], b"to the vehicle");

    // The first post is refused (500): the service posts it again.
    for answer in ["500 Internal Server Error", "200 OK"] {
        let (mut conn, _) = webhook.accept().unwrap();
        let (head, body) = read_http(&mut conn);
        assert!(head.starts_with("POST /hook HTTP/1.1"), "{head}");
        assert!(
            head.to_lowercase()
                .contains("content-type: application/json"),
            "{head}"
        );
        let post = MoPost::parse(Some("application/json"), &body).unwrap();
        assert_eq!(post.imei, IMEI);
        assert_eq!(post.data, mo_message);
        assert_eq!(post.momsn, Some(0));
        JwtVerifier::from_pem(EMULATOR_TEST_PUBLIC_KEY_PEM.as_bytes())
            .unwrap()
            .verify(&post)
            .unwrap();
        write!(
            conn,
            "HTTP/1.1 {answer}\r\nContent-Length: 0\r\nConnection: close\r\n\r\n"
        )
        .unwrap();
    }
}

fn hex_of(bytes: &[u8]) -> String {
    bytes.iter().map(|b| format!("{b:02x}")).collect()
}

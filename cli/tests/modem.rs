//! `goby modem emulate`: the printed pseudo-terminal speaks the Micro-Modem's
//! NMEA, and drivers on two emulated modems talk through the simulator.

use std::io::{BufRead, BufReader, Read, Write};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::{Duration, Instant};

use modemdriver::micromodem::nmea::NmeaSentence;
use modemdriver::micromodem::MicroModemDriver;
use modemdriver::{DriverConfig, DriverEvent, DriverStatus, ModemTransmission, TransmitOutcome};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::MicroModemConfig;

/// The emulator process, killed when dropped.
struct Emulator {
    child: Child,
    paths: Vec<String>,
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

/// Starts `goby modem emulate ARGS` and reads one `modem ID: PATH` line per modem.
fn emulate(args: &[&str], modems: usize) -> Emulator {
    emulate_to(args, modems, Stdio::inherit())
}

/// As [`emulate`], its standard error to `stderr`.
fn emulate_to(args: &[&str], modems: usize, stderr: Stdio) -> Emulator {
    let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["modem", "emulate"])
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .stdout(Stdio::piped())
        .stderr(stderr)
        .spawn()
        .expect("goby runs");
    let stdout = child.stdout.take().expect("piped");
    let (tx, rx) = mpsc::channel();
    std::thread::spawn(move || {
        for line in BufReader::new(stdout).lines().map_while(Result::ok) {
            if tx.send(line).is_err() {
                break;
            }
        }
    });
    let mut emulator = Emulator {
        child,
        paths: Vec::new(),
    };
    for _ in 0..modems {
        let line = rx
            .recv_timeout(Duration::from_secs(10))
            .expect("a `modem ID: PATH` line");
        let (_, path) = line.split_once(": ").expect("modem ID: PATH");
        emulator.paths.push(path.to_string());
    }
    emulator
}

#[test]
fn the_printed_pty_speaks_micromodem_nmea() {
    let emulator = emulate(&["--modem-id", "3", "--duration", "20"], 1);
    let mut tty = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .open(&emulator.paths[0])
        .expect("open the printed path");
    let (tx, rx) = mpsc::channel();
    let mut reader = tty.try_clone().expect("clone");
    std::thread::spawn(move || {
        let mut buf = [0u8; 256];
        while let Ok(n) = reader.read(&mut buf) {
            if n == 0 || tx.send(buf[..n].to_vec()).is_err() {
                break;
            }
        }
    });
    let query = NmeaSentence::new("CC", "CFQ", vec!["SRC".into()]).to_string();
    let clock = NmeaSentence::new(
        "CC",
        "CLK",
        ["2024", "01", "02", "03", "04", "05"]
            .map(String::from)
            .to_vec(),
    )
    .to_string();
    write!(tty, "{query}\r\n{clock}\r\n$CCCFQ,SRC*00\r\n").unwrap();
    let deadline = Instant::now() + Duration::from_secs(10);
    let mut text = String::new();
    while !(text.contains("$CACLK") && text.contains("$CAERR")) && Instant::now() < deadline {
        if let Ok(bytes) = rx.recv_timeout(Duration::from_millis(200)) {
            text.push_str(&String::from_utf8_lossy(&bytes));
        }
    }
    let lines: Vec<NmeaSentence> = text
        .split("\r\n")
        .filter_map(|l| NmeaSentence::parse(l.as_bytes()).ok())
        .collect();
    let addresses: Vec<String> = lines.iter().map(|s| s.address()).collect();
    let cfg = lines.iter().find(|s| s.address() == "CACFG").expect(&text);
    assert_eq!(cfg.fields, vec!["SRC", "3"]);
    let clk = lines.iter().find(|s| s.address() == "CACLK").expect(&text);
    assert_eq!(clk.fields, vec!["2024", "01", "02", "03", "04", "05"]);
    // The line with a wrong checksum is refused with an error.
    assert!(addresses.contains(&"CAERR".to_string()), "{text}");
}

/// The tty of an emulated modem, its lines read on a thread.
struct Tty {
    file: std::fs::File,
    bytes: mpsc::Receiver<Vec<u8>>,
    text: String,
}

impl Tty {
    fn open(path: &str) -> Tty {
        let file = std::fs::OpenOptions::new()
            .read(true)
            .write(true)
            .open(path)
            .expect("open the printed path");
        let (tx, bytes) = mpsc::channel();
        let mut reader = file.try_clone().expect("clone");
        std::thread::spawn(move || {
            let mut buf = [0u8; 256];
            while let Ok(n) = reader.read(&mut buf) {
                if n == 0 || tx.send(buf[..n].to_vec()).is_err() {
                    break;
                }
            }
        });
        Tty {
            file,
            bytes,
            text: String::new(),
        }
    }

    fn send(&mut self, sentence: NmeaSentence) {
        write!(self.file, "{sentence}\r\n").unwrap();
    }

    /// The next sentence from the modem (within 10 s).
    fn next(&mut self) -> NmeaSentence {
        let deadline = Instant::now() + Duration::from_secs(10);
        loop {
            if let Some((line, rest)) = self.text.split_once("\r\n") {
                let line = line.to_string();
                self.text = rest.to_string();
                if let Ok(s) = NmeaSentence::parse(line.as_bytes()) {
                    return s;
                }
                continue;
            }
            assert!(
                Instant::now() < deadline,
                "no line within 10 s: {:?}",
                self.text
            );
            if let Ok(bytes) = self.bytes.recv_timeout(Duration::from_millis(200)) {
                self.text.push_str(&String::from_utf8_lossy(&bytes));
            }
        }
    }
}

fn fields(v: &[&str]) -> Vec<String> {
    v.iter().map(|f| f.to_string()).collect()
}

#[test]
fn micromodem2_dialect_from_the_command_line() {
    let log = std::env::temp_dir().join(format!("goby-emulate-mm2-{}.log", std::process::id()));
    let emulator = emulate_to(
        &[
            "--micromodem",
            "2",
            "--modem-id",
            "3",
            "--transponder",
            "0,750,0",
            "--duration",
            "20",
        ],
        1,
        Stdio::from(std::fs::File::create(&log).expect("log file")),
    );
    let mut tty = Tty::open(&emulator.paths[0]);
    let rev = tty.next();
    assert_eq!(rev.address(), "CAREV");
    assert_eq!(rev.fields[1..], fields(&["INIT", "2.0.27087"]));
    assert_eq!(tty.next().fields[1..], fields(&["COPROC", "0.20.0.56"]));
    tty.send(NmeaSentence::new("CC", "CFQ", fields(&["TOP"])));
    // Too early: ignored, and told on standard error.
    tty.send(NmeaSentence::new(
        "CC",
        "CYC",
        fields(&["0", "3", "2", "1", "0", "1"]),
    ));
    let mut count = 0;
    loop {
        let s = tty.next();
        assert_eq!(s.address(), "CACFG", "{s}");
        count += 1;
        if s.fields[0] == "XST" {
            break;
        }
    }
    assert!(count > 60, "{count} parameters");
    // A REMUS interrogation of transponder A, 750 m away: 0.5 s one way.
    tty.send(NmeaSentence::new(
        "CC",
        "PDT",
        fields(&["1", "2", "0", "0", "2000", "1", "0", "0", "0"]),
    ));
    assert_eq!(tty.next().address(), "SNPDT");
    let tta = tty.next();
    assert_eq!(tta.address(), "SNTTA");
    assert_eq!(tta.fields[..4], fields(&["0.5000", "", "", ""]));
    drop(emulator);
    let stderr = std::fs::read_to_string(&log).unwrap_or_default();
    let _ = std::fs::remove_file(&log);
    assert!(
        stderr.contains("modem 3: ignored $CCCYC,0,3,2,1,0,1*"),
        "{stderr}"
    );
}

fn mm_config(id: i32, path: &str) -> DriverConfig {
    DriverConfig {
        modem_id: Some(id),
        serial_port: Some(path.to_string()),
        micromodem: Some(MicroModemConfig {
            response_timeout_ms: Some(1000),
            ..Default::default()
        }),
        ..Default::default()
    }
}

#[test]
fn drivers_talk_through_two_emulated_modems() {
    let emulator = emulate(
        &[
            "--modem-id",
            "1",
            "--modem-id",
            "2",
            "--spacing",
            "150",
            "--duration",
            "30",
        ],
        2,
    );
    let runtime = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .build()
        .unwrap();
    runtime.block_on(async {
        let limit = Duration::from_secs(15);
        let mut d1 = MicroModemDriver::start(&mm_config(1, &emulator.paths[0])).unwrap();
        let mut d2 = MicroModemDriver::start(&mm_config(2, &emulator.paths[1])).unwrap();
        d1.initiate_transmission(ModemTransmission {
            dest: Some(2),
            rate: Some(0),
            ack_requested: Some(true),
            r#type: Some(TransmissionType::Data as i32),
            ..Default::default()
        })
        .unwrap();
        let frame = b"bench test, no modem".to_vec();
        // Driver 1: answer the data request, then see the result and the ack.
        let one = async {
            let mut sent = false;
            loop {
                match d1.next_event().await.expect("running") {
                    DriverEvent::DataRequest(r) => {
                        let mut filled = r.template().clone();
                        filled.frame = vec![frame.clone()];
                        r.respond(filled);
                    }
                    DriverEvent::TransmitResult(r) => {
                        assert_eq!(r.outcome, TransmitOutcome::Sent);
                        sent = true;
                    }
                    DriverEvent::Received(mt) if mt.r#type() == TransmissionType::Ack => {
                        assert!(sent);
                        assert_eq!(mt.acked_frame, vec![0]);
                        return;
                    }
                    DriverEvent::Status(DriverStatus::Disconnected { reason }) => {
                        panic!("{reason}")
                    }
                    _ => {}
                }
            }
        };
        let two = async {
            loop {
                if let DriverEvent::Received(mt) = d2.next_event().await.expect("running") {
                    if mt.r#type() == TransmissionType::Data {
                        return mt;
                    }
                }
            }
        };
        let (got, ()) = tokio::time::timeout(limit, async { tokio::join!(two, one) })
            .await
            .expect("data and ack through the simulated channel in time");
        assert_eq!((got.src(), got.dest()), (1, 2));
        assert_eq!(got.frame, vec![frame.clone()]);
        d1.stop().await.unwrap();
        d2.stop().await.unwrap();
    });
}

#[test]
fn bad_options_are_refused() {
    let out = Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["modem", "emulate", "--modem-id", "0"])
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    assert_eq!(out.status.code(), Some(2));
    assert!(String::from_utf8_lossy(&out.stderr).contains("--modem-id"));
}

#[test]
fn sigterm_removes_the_links() {
    let dir = std::env::temp_dir().join(format!("goby-emulate-term-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let links = [dir.join("modem1"), dir.join("modem2")];
    let mut emulator = emulate(
        &[
            "--modem-id",
            "1",
            "--modem-id",
            "2",
            "--link",
            links[0].to_str().unwrap(),
            "--link",
            links[1].to_str().unwrap(),
        ],
        2,
    );
    for link in &links {
        assert!(link.symlink_metadata().is_ok(), "{} made", link.display());
    }
    let status = Command::new("kill")
        .args(["-TERM", &emulator.child.id().to_string()])
        .status()
        .unwrap();
    assert!(status.success());
    let deadline = Instant::now() + Duration::from_secs(20);
    let exit = loop {
        if let Some(exit) = emulator.child.try_wait().unwrap() {
            break exit;
        }
        assert!(
            Instant::now() < deadline,
            "goby modem emulate ignored SIGTERM"
        );
        std::thread::sleep(Duration::from_millis(20));
    };
    assert!(exit.success(), "{exit:?}");
    for link in &links {
        assert!(
            link.symlink_metadata().is_err(),
            "{} left behind",
            link.display()
        );
    }
    std::fs::remove_dir_all(&dir).unwrap();
}

/// `goby modem emulate --kind evologics`: two S2C modems on TCP; two
/// EvoLogics drivers exchange an acknowledged instant message through them.
#[test]
fn two_emulated_evologics_modems_on_tcp() {
    let emulator = emulate(
        &[
            "--kind",
            "evologics",
            "--modem-id",
            "1",
            "--modem-id",
            "2",
            "--tcp-port",
            "0",
            "--duration",
            "30",
        ],
        2,
    );
    let addrs: Vec<std::net::SocketAddr> = emulator
        .paths
        .iter()
        .map(|p| p.strip_prefix("tcp ").expect("tcp ADDR").parse().unwrap())
        .collect();
    let runtime = tokio::runtime::Runtime::new().unwrap();
    runtime.block_on(async {
        use modemdriver::evologics::EvologicsDriver;
        use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
        let config = |id: i32, addr: std::net::SocketAddr| DriverConfig {
            driver: Some(Kind::DriverName("EVOLOGICS_S2C".into())),
            modem_id: Some(id),
            connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
            tcp_server: Some(addr.ip().to_string()),
            tcp_port: Some(u32::from(addr.port())),
            ..Default::default()
        };
        let mut one = EvologicsDriver::start(&config(1, addrs[0])).await.unwrap();
        let mut two = EvologicsDriver::start(&config(2, addrs[1])).await.unwrap();
        let deadline = tokio::time::Instant::now() + Duration::from_secs(20);
        one.initiate_transmission(ModemTransmission {
            dest: Some(2),
            unique_id: Some(5),
            ..Default::default()
        })
        .unwrap();
        let mut acked = false;
        while !acked {
            let event = tokio::time::timeout_at(deadline, one.next_event())
                .await
                .expect("an ack in time")
                .unwrap();
            match event {
                DriverEvent::DataRequest(r) => {
                    let mut filled = r.template().clone();
                    filled.frame = vec![b"over tcp".to_vec()];
                    r.respond(filled);
                }
                DriverEvent::Received(t) if t.r#type() == TransmissionType::Ack => {
                    assert_eq!((t.src(), t.dest(), t.unique_id), (2, 1, Some(5)));
                    acked = true;
                }
                _ => {}
            }
        }
        loop {
            let event = tokio::time::timeout_at(deadline, two.next_event())
                .await
                .expect("the message in time")
                .unwrap();
            if let DriverEvent::Received(t) = event {
                assert_eq!(t.frame, vec![b"over tcp".to_vec()]);
                assert!(!t.evologics_receive_stat.is_empty());
                break;
            }
        }
    });
    // Options that cannot work are refused.
    for bad in [
        &["--kind", "evologics", "--modem-id", "255"][..],
        &["--kind", "evologics", "--busy", "2"],
        &["--kind", "evologics", "--link", "/tmp/x"],
    ] {
        let out = Command::new(env!("CARGO_BIN_EXE_goby"))
            .args(["modem", "emulate"])
            .args(bad)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{bad:?}");
    }
}

#[test]
fn the_help_describes_every_emulator() {
    let help = |args: &[&str]| {
        let out = Command::new(env!("CARGO_BIN_EXE_goby"))
            .args(args)
            .output()
            .unwrap();
        assert!(out.status.success(), "{args:?}");
        String::from_utf8_lossy(&out.stdout).into_owned()
    };
    let modem = help(&["modem", "--help"]);
    let goby = help(&["--help"]);
    let emulate = help(&["modem", "emulate", "--help"]);
    // Every emulated modem of the emulators' table, by its driver's title
    // and name.
    let kinds: Vec<&'static dyn modemdriver::kind::DriverKind> = std::iter::once("micromodem")
        .chain(emulators::kinds::STREAM.iter().map(|e| e.kind))
        .map(|k| modemdriver::built_in::by_short_name(k).expect("a driver built in"))
        .collect();
    assert!(
        kinds.len() >= 4,
        "the Micro-Modem, EvoLogics, Popoto, ATM-900 at least"
    );
    for text in [&modem, &goby, &emulate] {
        for kind in &kinds {
            let title = kind.about().title;
            assert!(text.contains(title), "{title} missing from:\n{text}");
        }
    }
    for text in [&modem, &goby] {
        assert!(text.contains("Iridium"), "{text}");
    }
    let names: Vec<String> = kinds
        .iter()
        .map(|k| k.about().named.name().to_string())
        .collect();
    for driver in names.iter().map(String::as_str).chain(["SIGTERM"]) {
        assert!(
            emulate.contains(driver),
            "{driver} missing from:\n{emulate}"
        );
    }
}

/// A free UDP port on 127.0.0.1 (bound, then released).
fn free_udp_port() -> u16 {
    std::net::UdpSocket::bind("127.0.0.1:0")
        .and_then(|s| s.local_addr())
        .expect("a free port")
        .port()
}

#[test]
fn modems_in_two_processes_joined_over_udp_range_by_their_spacing() {
    let (p1, p2) = (free_udp_port(), free_udp_port());
    let (l1, l2) = (p1.to_string(), p2.to_string());
    let (peer1, peer2) = (format!("2@127.0.0.1:{p2}"), format!("1@127.0.0.1:{p1}"));
    let one = emulate(
        &[
            "--modem-id",
            "1",
            "--udp-local",
            &l1,
            "--udp-peer",
            &peer1,
            "--spacing",
            "1500",
            "--duration",
            "40",
        ],
        1,
    );
    let two = emulate(
        &[
            "--modem-id",
            "2",
            "--udp-local",
            &l2,
            "--udp-peer",
            &peer2,
            "--spacing",
            "1500",
            "--duration",
            "40",
        ],
        1,
    );
    let mut tty1 = Tty::open(&one.paths[0]);
    let mut tty2 = Tty::open(&two.paths[0]);
    // Modem 2 sits 1500 m from modem 1: 1 s one way at 1500 m/s.
    tty1.send(NmeaSentence::new("CC", "MPC", fields(&["1", "2"])));
    let deadline = Instant::now() + Duration::from_secs(30);
    let reply = loop {
        assert!(Instant::now() < deadline, "no $CAMPR within 30 s");
        let s = tty1.next();
        if s.address() == "CAMPR" {
            break s;
        }
    };
    assert_eq!(reply.fields[..2], fields(&["2", "1"]), "{reply}");
    let owtt: f64 = reply.fields[2].parse().expect("a travel time");
    assert!((owtt - 1.0).abs() < 0.25, "one-way travel time {owtt} s");
    // The other process heard the ping.
    let heard = loop {
        let s = tty2.next();
        if s.address() == "CAMPA" {
            break s;
        }
    };
    assert_eq!(heard.fields[..2], fields(&["1", "2"]), "{heard}");
}

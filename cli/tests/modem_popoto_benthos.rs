//! `goby modem emulate --kind popoto` (two Popoto modems, their JSON
//! command interfaces on TCP) and `--kind benthos` (two ATM-900s on
//! pseudo-terminals, their serial lines): two drivers exchange an
//! acknowledged message through each pair; options that cannot work are
//! refused.

use std::io::{BufRead, BufReader};
use std::process::{Child, Command, Stdio};
use std::sync::mpsc;
use std::time::Duration;

use modemdriver::{Driver, DriverConfig, DriverEvent, ModemTransmission};
use protos::goby::acomms::protobuf::driver_config::{ConnectionType, Driver as Kind};
use protos::goby::acomms::protobuf::modem_transmission::TransmissionType;
use protos::goby::acomms::protobuf::{BenthosConfig, DriverType};

/// A running `goby modem emulate` and the interfaces it printed.
struct Emulator {
    child: Child,
    shown: Vec<String>,
}

impl Drop for Emulator {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

fn emulate(args: &[&str], modems: usize) -> Emulator {
    let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["modem", "emulate"])
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .stdout(Stdio::piped())
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
    let mut e = Emulator {
        child,
        shown: Vec::new(),
    };
    for _ in 0..modems {
        let line = rx
            .recv_timeout(Duration::from_secs(10))
            .expect("a `modem ID: WHERE` line");
        let (_, shown) = line.split_once(": ").expect("modem ID: WHERE");
        e.shown.push(shown.to_string());
    }
    e
}

/// `one` sends "over the emulator" to node 2 asking for an ack; waits for
/// the ack and for `two`'s reception.
async fn exchange(one: &mut Driver, two: &mut Driver, rate: i32) {
    let deadline = tokio::time::Instant::now() + Duration::from_secs(40);
    one.initiate_transmission(ModemTransmission {
        dest: Some(2),
        rate: Some(rate),
        unique_id: Some(5),
        ..Default::default()
    })
    .unwrap();
    let mut acked = false;
    let mut heard = false;
    while !(acked && heard) {
        tokio::select! {
            event = one.next_event() => match event.unwrap() {
                DriverEvent::DataRequest(r) => {
                    let mut filled = r.template().clone();
                    filled.frame = vec![b"over the emulator".to_vec()];
                    r.respond(filled);
                }
                DriverEvent::Received(t) if t.r#type() == TransmissionType::Ack => {
                    assert_eq!((t.src(), t.dest(), t.unique_id), (2, 1, Some(5)));
                    acked = true;
                }
                _ => {}
            },
            event = two.next_event() => {
                if let DriverEvent::Received(t) = event.unwrap() {
                    if t.r#type() == TransmissionType::Data {
                        assert_eq!(t.frame, vec![b"over the emulator".to_vec()]);
                        heard = true;
                    }
                }
            },
            () = tokio::time::sleep_until(deadline) => panic!("acked {acked}, heard {heard}"),
        }
    }
}

fn refused(args: &[&str]) {
    let out = Command::new(env!("CARGO_BIN_EXE_goby"))
        .args(["modem", "emulate"])
        .args(args)
        .env_remove("RUST_BACKTRACE")
        .output()
        .unwrap();
    assert!(!out.status.success(), "{args:?}");
    assert!(!out.stderr.is_empty(), "{args:?}: says why");
}

#[test]
fn two_emulated_popoto_modems_on_tcp() {
    let emulator = emulate(
        &[
            "--kind",
            "popoto",
            "--modem-id",
            "1",
            "--modem-id",
            "2",
            "--tcp-port",
            "0",
            "--spacing",
            "300",
            "--duration",
            "60",
        ],
        2,
    );
    let addrs: Vec<std::net::SocketAddr> = emulator
        .shown
        .iter()
        .map(|p| p.strip_prefix("tcp ").expect("tcp ADDR").parse().unwrap())
        .collect();
    tokio::runtime::Runtime::new().unwrap().block_on(async {
        use modemdriver::popoto::PopotoDriver;
        let config = |id: i32, addr: std::net::SocketAddr| DriverConfig {
            driver: Some(Kind::DriverType(DriverType::DriverPopoto as i32)),
            modem_id: Some(id),
            connection_type: Some(ConnectionType::ConnectionTcpAsClient as i32),
            tcp_server: Some(addr.ip().to_string()),
            tcp_port: Some(u32::from(addr.port())),
            ..Default::default()
        };
        let mut one = PopotoDriver::start(&config(1, addrs[0])).await.unwrap();
        let mut two = PopotoDriver::start(&config(2, addrs[1])).await.unwrap();
        exchange(&mut one, &mut two, 4).await;
    });
    for bad in [
        &["--kind", "popoto", "--modem-id", "255"][..],
        &["--kind", "popoto", "--busy", "2"],
        &["--kind", "popoto", "--link", "/tmp/x"],
        &["--kind", "popoto", "--usbl"],
    ] {
        refused(bad);
    }
}

#[test]
fn two_emulated_benthos_modems_on_ptys() {
    let dir = std::env::temp_dir().join(format!("goby-cli-benthos-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let links = [dir.join("atm1"), dir.join("atm2")];
    let emulator = emulate(
        &[
            "--kind",
            "benthos",
            "--modem-id",
            "1",
            "--modem-id",
            "2",
            "--link",
            links[0].to_str().unwrap(),
            "--link",
            links[1].to_str().unwrap(),
            "--duration",
            "60",
        ],
        2,
    );
    assert_eq!(emulator.shown[0], links[0].display().to_string());
    tokio::runtime::Runtime::new().unwrap().block_on(async {
        use modemdriver::benthos::BenthosDriver;
        let config = |id: i32, path: &std::path::Path| DriverConfig {
            driver: Some(Kind::DriverType(DriverType::DriverBenthosAtm900 as i32)),
            modem_id: Some(id),
            connection_type: Some(ConnectionType::ConnectionSerial as i32),
            serial_port: Some(path.display().to_string()),
            benthos: Some(BenthosConfig::default()),
            ..Default::default()
        };
        let mut one = BenthosDriver::start(&config(1, &links[0])).await.unwrap();
        let mut two = BenthosDriver::start(&config(2, &links[1])).await.unwrap();
        exchange(&mut one, &mut two, 8).await;
    });
    drop(emulator);
    let _ = std::fs::remove_dir_all(&dir);
    for bad in [
        &["--kind", "benthos", "--modem-id", "0"][..],
        &["--kind", "benthos", "--pty"],
        &["--kind", "benthos", "--tcp-port", "0", "--link", "/tmp/x"],
    ] {
        refused(bad);
    }
}

/// Emulated SeaTrac beacons as far apart as a beacon's range timeout
/// (1000 m, the default `--spacing`) answer no request in time: the
/// emulator says so when it starts, and not at 500 m.
#[test]
fn seatracs_at_their_range_timeout_are_told_of() {
    let stderr_of = |spacing: Option<&str>| {
        let mut args = vec![
            "modem",
            "emulate",
            "--kind",
            "seatrac",
            "--modem-id",
            "1",
            "--modem-id",
            "2",
        ];
        if let Some(s) = spacing {
            args.extend(["--spacing", s]);
        }
        let mut child = Command::new(env!("CARGO_BIN_EXE_goby"))
            .args(&args)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("goby runs");
        let mut lines = BufReader::new(child.stdout.take().expect("piped")).lines();
        for _ in 0..2 {
            let line = lines.next().expect("a `modem ID: WHERE` line").unwrap();
            assert!(line.starts_with("modem "), "{line}");
        }
        let _ = child.kill();
        let out = child.wait_with_output().expect("ends");
        String::from_utf8_lossy(&out.stderr).into_owned()
    };
    let told = stderr_of(None);
    assert!(
        told.contains("note: beacons 1000 m apart (--spacing) are at or past a SeaTrac's range timeout (1000 m)"),
        "{told}"
    );
    let near = stderr_of(Some("500"));
    assert!(!near.contains("range timeout"), "{near}");
}

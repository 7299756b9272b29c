//! The emulator as a Micro-Modem 2, seen from the host's side of real
//! pseudo-terminals: plain NMEA lines written as a host writes them, the
//! modem's lines checked in order. Start-up (revision, configuration echo,
//! clock), rate-0 and rate-1 cycles with acknowledgement between two
//! emulated modems 1000 m apart, a bad CRC, a reset mid-packet, Flexible
//! Data Protocol packets and long-baseline ranging.

use std::time::Duration;

use emulators::micromodem::{
    self as emulator, geometry, mm2, nvram, EmulatorConfig, EmulatorControl, EmulatorHandle,
    EmulatorPort, Geometry, Node, Transponder,
};
use modemdriver::link::serial::{self, SerialLineLink};
use modemdriver::link::Link;
use modemdriver::micromodem::nmea::{checksum, NmeaSentence};
use modemdriver::sim::medium::Medium;
use modemdriver::sim::reception::Position;
use modemdriver::sim::SimulatorDriver;
use modemdriver::time::now_micros;
use modemdriver::DriverConfig;
use protos::goby::acomms::protobuf::simulator_driver_config::NodePosition;
use protos::goby::acomms::protobuf::SimulatorDriverConfig;

/// Longest wait for any one line.
const LIMIT: Duration = Duration::from_secs(15);
/// Metres between the two modems.
const RANGE: f64 = 1000.0;

/// The host's end of one emulated modem's pseudo-terminal.
struct Host {
    link: SerialLineLink,
    name: String,
}

impl Host {
    async fn open(handle: &mut EmulatorHandle, name: &str) -> Host {
        let path = handle.path().await.expect("device");
        Host {
            link: serial::open(&path, 19_200, b"\r\n").expect("open pty"),
            name: name.into(),
        }
    }

    /// Writes `body` (e.g. `CCCYC,0,1,2,0,1,1`) as a sentence.
    async fn send(&mut self, body: &str) {
        let line = format!("${body}*{:02X}", checksum(body.as_bytes()));
        self.link.send(line.as_bytes(), &()).await.expect("write");
    }

    /// The modem's next line.
    async fn next(&mut self) -> NmeaSentence {
        let (line, ()) = tokio::time::timeout(LIMIT, self.link.recv())
            .await
            .unwrap_or_else(|_| panic!("{}: no line within {LIMIT:?}", self.name))
            .expect("read");
        NmeaSentence::parse(&line)
            .unwrap_or_else(|e| panic!("{}: {e}: {:?}", self.name, String::from_utf8_lossy(&line)))
    }

    /// The next line, which must have `address`.
    async fn expect(&mut self, address: &str) -> NmeaSentence {
        let s = self.next().await;
        assert_eq!(s.address(), address, "{}: got {s}", self.name);
        s
    }

    /// The next line, which must be exactly `body` (checksum aside).
    async fn expect_line(&mut self, body: &str) {
        let s = self.next().await;
        let text = s.to_string();
        let got = text[1..text.len() - 3].to_string();
        assert_eq!(got, body, "{}", self.name);
    }
}

fn config(id: u32) -> EmulatorConfig {
    EmulatorConfig {
        revision_interval: Duration::from_secs(3600),
        packet_overhead: Duration::from_millis(100),
        config_line_interval: Duration::from_millis(40),
        ..EmulatorConfig::micromodem2(id)
    }
}

/// Modem 1 at the origin, modem 2 `RANGE` m east moving at `velocity2`.
fn geometry_of_two(velocity2: [f64; 3]) -> Geometry {
    let mut g = Geometry::default();
    for (id, x, velocity) in [(1, 0.0, [0.0; 3]), (2, RANGE, velocity2)] {
        g.nodes.insert(
            id,
            Node {
                position: Position::new(x, 0.0, 0.0),
                velocity,
            },
        );
    }
    g
}

/// Two emulated Micro-Modem 2s on the in-process channel simulator.
async fn pair() -> (EmulatorHandle, EmulatorHandle, Host, Host) {
    pair_moving([0.0; 3]).await
}

/// As [`pair`], modem 2 moving at `velocity2` (m/s) as far as the modems'
/// Doppler goes.
async fn pair_moving(velocity2: [f64; 3]) -> (EmulatorHandle, EmulatorHandle, Host, Host) {
    let medium = Medium::new();
    let mut handles = Vec::new();
    for id in [1u32, 2] {
        let sim = DriverConfig {
            modem_id: Some(id as i32),
            simulator: Some(SimulatorDriverConfig {
                node: vec![
                    NodePosition {
                        modem_id: 1,
                        x: Some(0.0),
                        ..Default::default()
                    },
                    NodePosition {
                        modem_id: 2,
                        x: Some(RANGE),
                        ..Default::default()
                    },
                ],
                packet_overhead_seconds: Some(0.1),
                ..Default::default()
            }),
            ..Default::default()
        };
        let backend = SimulatorDriver::start_on(&sim, medium.clone()).expect("simulator");
        let cfg = EmulatorConfig {
            geometry: geometry_of_two(velocity2),
            ..config(id)
        };
        handles
            .push(emulator::start(cfg, EmulatorPort::Pty { link: None }, Some(backend)).unwrap());
    }
    let mut e2 = handles.pop().unwrap();
    let mut e1 = handles.pop().unwrap();
    let mut h1 = Host::open(&mut e1, "modem 1").await;
    let mut h2 = Host::open(&mut e2, "modem 2").await;
    for h in [&mut h1, &mut h2] {
        let init = h.expect("CAREV").await;
        assert_eq!(init.field(1), Some("INIT"));
        h.expect("CAREV").await;
    }
    (e1, e2, h1, h2)
}

fn field(s: &NmeaSentence, i: usize) -> &str {
    s.field(i).unwrap_or_else(|| panic!("{s} has no field {i}"))
}

/// Checks a `$CACST` (version 6, as firmware 2.0 writes it): mode, rate, src, dest, packet type,
/// frames and bad frames, and for PSK the SNR from the range (for FSK the
/// data quality factor from it).
#[allow(clippy::too_many_arguments)]
fn check_cst(
    s: &NmeaSentence,
    mode: u32,
    rate: u32,
    src: u32,
    dest: u32,
    kind: u32,
    frames: u32,
    bad: u32,
) {
    assert_eq!(s.address(), "CACST", "{s}");
    assert_eq!(s.fields.len(), 30, "{s}");
    assert_eq!(field(s, 0), "6");
    assert_eq!(field(s, 1), mode.to_string(), "mode of {s}");
    assert_eq!(field(s, 13), rate.to_string(), "rate of {s}");
    assert_eq!(field(s, 14).parse::<u32>().unwrap(), src, "src of {s}");
    assert_eq!(field(s, 15).parse::<u32>().unwrap(), dest, "dest of {s}");
    assert_eq!(field(s, 17), kind.to_string(), "packet type of {s}");
    assert_eq!(field(s, 18), frames.to_string(), "frames of {s}");
    assert_eq!(field(s, 19), bad.to_string(), "bad frames of {s}");
    let snr = geometry::snr_db(RANGE);
    if kind == 1 || kind == 2 {
        // FSK: no PSK SNR; a data quality factor from the SNR instead.
        assert_eq!(field(s, 21), "-1.0", "{s}");
        let dqf: i32 = field(s, 25).parse().unwrap();
        let expected = (255.0 * (1.0 - (-snr / 10.0).exp())).round() as i32;
        assert_eq!(dqf, expected, "{s}");
    } else {
        assert_eq!(field(s, 21), format!("{snr:.1}"), "SNR in of {s}");
        assert_eq!(field(s, 25), "-01", "{s}");
    }
}

/// Checks a `$CAXST` (version 6): rate, src, dest, ack, frames expected and
/// sent, packet type, bytes.
#[allow(clippy::too_many_arguments)]
fn check_xst(
    s: &NmeaSentence,
    rate: u32,
    src: u32,
    dest: u32,
    ack: u32,
    frames: (u32, u32),
    kind: u32,
    bytes: u32,
) {
    assert_eq!(s.address(), "CAXST", "{s}");
    assert_eq!(s.fields.len(), 16, "{s}");
    assert_eq!(field(s, 0), "6");
    let got: Vec<&str> = s.fields[8..16].iter().map(String::as_str).collect();
    let want = [rate, src, dest, ack, frames.0, frames.1, kind, bytes].map(|v| v.to_string());
    assert_eq!(got, want, "{s}");
}

#[tokio::test]
async fn start_up_revision_configuration_echo_and_clock() {
    let mut e = emulator::start(config(1), EmulatorPort::Pty { link: None }, None).unwrap();
    let mut h = Host::open(&mut e, "modem").await;
    // A Micro-Modem 2 names its firmware and its coprocessor's.
    let rev = h.expect("CAREV").await;
    assert_eq!(&rev.fields[1..], ["INIT", "2.0.27087"]);
    assert_eq!(field(&rev, 0).len(), 6, "hhmmss: {rev}");
    let rev = h.expect("CAREV").await;
    assert_eq!(&rev.fields[1..], ["COPROC", "0.20.0.56"]);

    // The whole NVRAM, one line per parameter; a cycle asked for meanwhile
    // is ignored.
    h.send("CCCFQ,ALL").await;
    h.send("CCCYC,0,1,2,1,0,1").await;
    let table = nvram::micromodem2(1);
    let mut names: Vec<&str> = table.iter().map(|(k, _)| k.as_str()).collect();
    names.sort_unstable();
    assert!(names.len() > 60);
    for name in &names {
        let cfg = h.expect("CACFG").await;
        assert_eq!(field(&cfg, 0), *name);
        if *name == "SRC" {
            assert_eq!(field(&cfg, 1), "1");
        }
    }
    // What comes next answers the next command, not the ignored cycle.
    h.send("CCCFQ,SRC").await;
    h.expect_line("CACFG,SRC,1").await;
    assert_eq!(e.ignored().len(), 1);
    assert!(e.ignored()[0].starts_with("$CCCYC,0,1,2,1,0,1*"));

    // TOP: the three-letter parameters only.
    h.send("CCCFQ,TOP").await;
    for name in names.iter().filter(|n| !n.contains('.')) {
        assert_eq!(field(&h.expect("CACFG").await, 0), *name);
    }
    h.send("CCCFQ,SRC").await;
    h.expect_line("CACFG,SRC,1").await;

    // The clock: set at the next second, answered, the source reported.
    let set = now_micros() + 1_000_000;
    let iso = mm2::iso(set - set % 1_000_000, false);
    h.send(&format!("CCTMS,{iso}Z,0")).await;
    h.expect_line(&format!("CATMS,0,{iso}Z")).await;
    let tmg = h.expect("CATMG").await;
    assert_eq!(&tmg.fields[1..], ["RTC_USER_SET", "RTC"]);
    h.send("CCTMQ,0").await;
    let tmq = h.expect("CATMQ").await;
    assert_eq!(&tmq.fields[1..], ["RTC_USER_SET", "RTC"]);
    // The older command is still understood.
    h.send("CCCLK,2026,11,30,1,2,3").await;
    h.expect_line("CACLK,2026,11,30,01,02,03").await;
    e.stop().await;
}

#[tokio::test]
async fn rate0_cycle_with_ack_sends_the_cycle_initialization_first() {
    let (e1, e2, mut h1, mut h2) = pair().await;
    h1.send("CCCYC,0,1,2,0,1,1").await;
    h1.expect_line("CACYC,0,1,2,0,1,1").await;
    // The cycle-initialization packet, then the data request.
    h1.expect_line("CATXP,0").await;
    h1.expect_line("CATXF,0").await;
    check_xst(&h1.expect("CAXST").await, 0, 1, 2, 1, (1, 1), 2, 0);
    let drq = h1.expect("CADRQ").await;
    assert_eq!(&drq.fields[1..], ["1", "2", "1", "32", "1"]);
    h1.send("CCTXD,1,2,1,48454C4C4F").await;
    h1.expect_line("CATXD,1,2,1,5").await;
    h1.expect_line("CATXP,5").await;
    h1.expect_line("CATXF,5").await;
    check_xst(&h1.expect("CAXST").await, 0, 1, 2, 1, (1, 1), 1, 5);

    // The receiver: the cycle announced, then the data, each with statistics.
    h2.expect_line("CACYC,0,1,2,0,1,1").await;
    check_cst(&h2.expect("CACST").await, 0, 0, 1, 2, 2, 1, 0);
    h2.expect_line("CARXD,1,2,1,1,48454C4C4F").await;
    check_cst(&h2.expect("CACST").await, 0, 0, 1, 2, 1, 1, 0);
    // Its acknowledgement on the water.
    h2.expect_line("CATXP,0").await;
    h2.expect_line("CATXF,0").await;
    check_xst(&h2.expect("CAXST").await, 0, 2, 1, 0, (0, 0), 2, 0);

    // The sender hears it.
    h1.expect_line("CAACK,2,1,1,0").await;
    check_cst(&h1.expect("CACST").await, 0, 0, 2, 1, 2, 1, 0);
    e1.stop().await;
    e2.stop().await;
}

#[tokio::test]
async fn rate1_cycle_with_ack_and_then_a_bad_crc() {
    let (e1, e2, mut h1, mut h2) = pair().await;
    h1.send("CCCYC,0,1,2,1,1,2").await;
    h1.expect_line("CACYC,0,1,2,1,1,2").await;
    let drq = h1.expect("CADRQ").await;
    assert_eq!(&drq.fields[1..], ["1", "2", "1", "64", "1"]);
    h1.send("CCTXD,1,2,1,AABB").await;
    h1.expect_line("CATXD,1,2,1,2").await;
    let drq = h1.expect("CADRQ").await;
    assert_eq!(field(&drq, 5), "2");
    h1.send("CCTXD,1,2,1,CCDDEE").await;
    h1.expect_line("CATXD,1,2,1,3").await;
    h1.expect_line("CATXP,5").await;
    h1.expect_line("CATXF,5").await;
    check_xst(&h1.expect("CAXST").await, 1, 1, 2, 1, (2, 2), 3, 5);

    h2.expect_line("CACYC,0,1,2,1,1,2").await;
    h2.expect_line("CARXD,1,2,1,1,AABB").await;
    h2.expect_line("CARXD,1,2,1,2,CCDDEE").await;
    let cst = h2.expect("CACST").await;
    check_cst(&cst, 0, 1, 1, 2, 3, 2, 0);
    assert_eq!(field(&cst, 26), "0.00", "Doppler between still modems");
    h2.expect_line("CATXP,0").await;
    h2.expect_line("CATXF,0").await;
    check_xst(&h2.expect("CAXST").await, 1, 2, 1, 0, (0, 0), 4, 0);
    h1.expect_line("CAACK,2,1,1,0").await;
    h1.expect_line("CAACK,2,1,2,0").await;
    check_cst(&h1.expect("CACST").await, 0, 1, 2, 1, 4, 1, 0);

    // The first frame of the next packet fails its CRC: reported, counted
    // in the statistics, not acknowledged.
    e2.control(EmulatorControl::BadCrc(1));
    h1.send("CCCYC,0,1,2,1,1,2").await;
    h1.expect("CACYC").await;
    h1.expect("CADRQ").await;
    h1.send("CCTXD,1,2,1,01").await;
    h1.expect("CATXD").await;
    h1.expect("CADRQ").await;
    h1.send("CCTXD,1,2,1,02").await;
    h1.expect("CATXD").await;
    h1.expect_line("CATXP,2").await;
    h1.expect_line("CATXF,2").await;
    h1.expect("CAXST").await;
    h2.expect_line("CACYC,0,1,2,1,1,2").await;
    h2.expect_line("CAMSG,BAD_CRC,1").await;
    h2.expect_line("CARXD,1,2,1,2,02").await;
    let cst = h2.expect("CACST").await;
    check_cst(&cst, 1, 1, 1, 2, 3, 2, 1);
    assert_eq!(field(&cst, 16), "3", "PSK error: bad CRC in a frame");
    h2.expect_line("CATXP,0").await;
    h2.expect_line("CATXF,0").await;
    h2.expect("CAXST").await;
    h1.expect_line("CAACK,2,1,2,0").await;
    h1.expect("CACST").await;
    e1.stop().await;
    e2.stop().await;
}

#[tokio::test]
async fn a_reset_aborts_the_packet_on_the_water() {
    let (e1, e2, mut h1, mut h2) = pair().await;
    e1.control(EmulatorControl::ResetMidPacket(1));
    h1.send("CCCYC,0,1,2,1,0,1").await;
    h1.expect("CACYC").await;
    h1.expect("CADRQ").await;
    h1.send("CCTXD,1,2,0,0102").await;
    h1.expect("CATXD").await;
    h1.expect_line("CATXP,2").await;
    // No $CATXF, no $CAXST: the modem restarts.
    assert_eq!(field(&h1.expect("CAREV").await, 1), "INIT");
    assert_eq!(field(&h1.expect("CAREV").await, 1), "COPROC");
    // The receiver heard nothing of it: its next line answers our query.
    h2.send("CCCFQ,SRC").await;
    h2.expect_line("CACFG,SRC,2").await;
    assert!(e1
        .air_log()
        .iter()
        .any(|a| a.kind == emulator::AirKind::Aborted));
    e1.stop().await;
    e2.stop().await;
}

#[tokio::test]
async fn flexible_data_packets_and_their_limits() {
    // Modem 2 heads for modem 1 at 1.5 m/s: they close at 1.5 m/s.
    let (e1, e2, mut h1, mut h2) = pair_moving([-1.5, 0.0, 0.0]).await;
    h1.send("CCTDP,2,1,0,0,DEADBEEF").await;
    h1.expect_line("CATDP,0,1,2,1,0,0,4").await;
    h1.expect_line("CATXP,4").await;
    h1.expect_line("CATXF,4").await;
    check_xst(&h1.expect("CAXST").await, 1, 1, 2, 0, (1, 1), 5, 4);
    h2.expect_line("CARDP,1,2,1,0,0,,1;4;DEADBEEF").await;
    let cst = h2.expect("CACST").await;
    check_cst(&cst, 0, 1, 1, 2, 5, 1, 0);
    assert_eq!(field(&cst, 26), "1.50", "Doppler of closing modems");

    // 70 bytes at rate 1 take two 64-byte frames.
    let data: String = (0..70u8).map(|b| format!("{b:02X}")).collect();
    h1.send(&format!("CCTDP,2,1,0,0,{data}")).await;
    h1.expect_line("CATDP,0,2,2,1,0,0,70").await;
    h1.expect_line("CATXP,70").await;
    h1.expect_line("CATXF,70").await;
    check_xst(&h1.expect("CAXST").await, 1, 1, 2, 0, (2, 2), 5, 70);
    let rdp = h2.expect("CARDP").await;
    assert_eq!(
        field(&rdp, 6),
        format!("1;64;{};1;6;{}", &data[..128], &data[128..])
    );
    check_cst(&h2.expect("CACST").await, 0, 1, 1, 2, 5, 2, 0);

    // Refused: a rate FDP lacks, and more than rate 1 carries.
    h1.send("CCTDP,2,2,0,0,AB").await;
    h1.expect_line("CATDP,1,3,2,2,0,0,0").await;
    assert!(field(&h1.expect("CAERR").await, 3).contains("field 1 (rate)"));
    let big = "00".repeat(193);
    h1.send(&format!("CCTDP,2,1,0,0,{big}")).await;
    h1.expect_line("CATDP,1,4,2,1,0,0,0").await;
    assert!(field(&h1.expect("CAERR").await, 3).contains("193 bytes"));
    h1.send("CCCFQ,SRC").await;
    h1.expect_line("CACFG,SRC,1").await;
    e1.stop().await;
    e2.stop().await;
}

#[tokio::test]
async fn long_baseline_travel_times_follow_the_geometry() {
    let at = |x: f64, y: f64| Position::new(x, y, 0.0);
    let mut g = Geometry::default();
    g.nodes.insert(
        1,
        Node {
            position: at(100.0, 100.0),
            velocity: [0.0; 3],
        },
    );
    g.transponders = vec![
        Transponder {
            position: at(100.0, 850.0),
            frequency: Some(25_000),
        },
        Transponder {
            position: at(1300.0, 600.0),
            frequency: Some(26_500),
        },
        Transponder {
            position: at(400.0, 500.0),
            frequency: None,
        },
        Transponder {
            position: at(3100.0, 100.0),
            frequency: None,
        },
    ];
    // One-way travel times, as the modem reports them.
    let one_way = |t: usize| g.transponders[t].position.distance(&at(100.0, 100.0)) / 1500.0;
    let expected: Vec<String> = (0..4).map(|t| format!("{:.4}", one_way(t))).collect();
    let cfg = EmulatorConfig {
        geometry: g.clone(),
        ..config(1)
    };
    let mut e = emulator::start(cfg, EmulatorPort::Pty { link: None }, None).unwrap();
    let mut h = Host::open(&mut e, "modem").await;
    h.expect("CAREV").await;
    h.expect("CAREV").await;

    // REMUS: A, B and D enabled; D (6 km round trip) is beyond the 3 s
    // timeout.
    h.send("CCPDT,1,2,0,0,3000,1,1,0,1").await;
    h.expect_line("SNPDT,1,2,0,0,3000,1,1,0,1").await;
    let tta = h.expect("SNTTA").await;
    assert_eq!(
        &tta.fields[..4],
        [expected[0].as_str(), expected[1].as_str(), "", ""]
    );
    assert_eq!(field(&tta, 4).len(), 9, "hhmmss.ss: {tta}");

    // Narrowband, by reply frequency: B's and A's frequencies in slots A and
    // B, slot C for the transponder without one.
    h.send("CCPNT,24000,5,5,3000,26500,25000,1,0,1").await;
    h.expect_line("SNPNT,24000,5,5,3000,26500,25000,1,0,1")
        .await;
    let tta = h.expect("SNTTA").await;
    assert_eq!(
        &tta.fields[..4],
        [
            expected[1].as_str(),
            expected[0].as_str(),
            expected[2].as_str(),
            ""
        ]
    );
    // A bad interrogation names its field.
    h.send("CCPDT,1,2,0,0,soon,1,1,0,1").await;
    assert!(field(&h.expect("CAERR").await, 3).contains("field 4 (timeout)"));
    e.stop().await;
}

#[tokio::test]
async fn a_lost_ack_is_sent_but_never_heard() {
    let (e1, e2, mut h1, mut h2) = pair().await;
    e2.control(EmulatorControl::LoseAcks(1));
    h1.send("CCCYC,0,1,2,1,1,1").await;
    h1.expect("CACYC").await;
    h1.expect("CADRQ").await;
    h1.send("CCTXD,1,2,1,0A0B").await;
    h1.expect("CATXD").await;
    h1.expect_line("CATXP,2").await;
    h1.expect_line("CATXF,2").await;
    h1.expect("CAXST").await;
    h2.expect_line("CACYC,0,1,2,1,1,1").await;
    h2.expect_line("CARXD,1,2,1,1,0A0B").await;
    h2.expect("CACST").await;
    // The receiver sends its acknowledgement ...
    h2.expect_line("CATXP,0").await;
    h2.expect_line("CATXF,0").await;
    h2.expect("CAXST").await;
    // ... and then a packet of its own, which reaches modem 1 after where the
    // acknowledgement would have: modem 1 hears that packet, no $CAACK.
    h2.send("CCTDP,1,1,0,0,C0FFEE").await;
    h2.expect("CATDP").await;
    h1.expect_line("CARDP,2,1,1,0,0,,1;3;C0FFEE").await;
    h1.expect("CACST").await;
    e1.stop().await;
    e2.stop().await;
}

#[tokio::test]
async fn a_packet_waits_for_the_one_on_the_water() {
    let (e1, e2, mut h1, mut h2) = pair().await;
    h1.send("CCCYC,0,1,2,1,0,1").await;
    h1.expect("CACYC").await;
    h1.expect("CADRQ").await;
    h1.send("CCTXD,1,2,0,0102").await;
    h1.expect("CATXD").await;
    h1.expect_line("CATXP,2").await;
    // Asked for while the data packet (a full rate-1 packet: seconds) is on
    // the water: taken at once, sent after it.
    h1.send("CCTDP,2,1,0,0,DEADBEEF").await;
    h1.expect_line("CATDP,0,1,2,1,0,0,4").await;
    h1.expect_line("CATXF,2").await;
    check_xst(&h1.expect("CAXST").await, 1, 1, 2, 0, (1, 1), 3, 2);
    h1.expect_line("CATXP,4").await;
    h1.expect_line("CATXF,4").await;
    check_xst(&h1.expect("CAXST").await, 1, 1, 2, 0, (1, 1), 5, 4);
    h2.expect("CACYC").await;
    h2.expect_line("CARXD,1,2,0,1,0102").await;
    h2.expect("CACST").await;
    h2.expect_line("CARDP,1,2,1,0,0,,1;4;DEADBEEF").await;
    h2.expect("CACST").await;
    e1.stop().await;
    e2.stop().await;
}

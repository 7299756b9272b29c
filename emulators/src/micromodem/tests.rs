//! The emulated modem without any I/O: host lines in, the modem's lines
//! out; packets handed from one modem's water to the other's by hand, on
//! tokio's paused clock.
//!
//! Among them, the case a modem's own driver never shows: a host that, as
//! Goby3's driver does with `CST` on, hands a reception (or an ack) up only
//! when the modem's `$CACST` for it arrives ([`StatsGatedHost`]).

use std::time::Duration;

use protos::goby::acomms::protobuf::ModemTransmission;
use tokio::time::Instant;

use super::modem::Modem;
use super::stats::StatsLayout;
use super::{Dialect, EmulatorConfig};
use modemdriver::driver::DriverEvent;
use modemdriver::micromodem::nmea::{checksum, NmeaSentence};

fn config(dialect: Dialect, id: u32) -> EmulatorConfig {
    let base = match dialect {
        Dialect::MicroModem1 => EmulatorConfig {
            modem_id: id,
            ..EmulatorConfig::default()
        },
        Dialect::MicroModem2 => EmulatorConfig::micromodem2(id),
    };
    EmulatorConfig {
        packet_overhead: Duration::from_millis(100),
        config_line_interval: Duration::from_millis(5),
        ..base
    }
}

fn modem(config: EmulatorConfig) -> Modem {
    let mut m = Modem::new(config, Default::default(), Default::default());
    m.has_backend = true;
    m
}

fn line(body: &str) -> Vec<u8> {
    format!("${body}*{:02X}", checksum(body.as_bytes())).into_bytes()
}

/// The sentence without `$` and checksum.
fn body(s: &NmeaSentence) -> String {
    let text = s.to_string();
    text[1..text.len() - 3].to_string()
}

/// Two modems on one stretch of water, their hosts' lines collected.
struct Pair {
    m: [Modem; 2],
    said: [Vec<NmeaSentence>; 2],
}

impl Pair {
    fn new(a: EmulatorConfig, b: EmulatorConfig) -> Pair {
        Pair {
            m: [modem(a), modem(b)],
            said: [Vec::new(), Vec::new()],
        }
    }

    fn host(&mut self, i: usize, body: &str) {
        self.m[i].line(&line(body), true);
        self.collect();
    }

    fn collect(&mut self) {
        for i in 0..2 {
            self.said[i].extend(std::mem::take(&mut self.m[i].out));
            let sent: Vec<ModemTransmission> = std::mem::take(&mut self.m[i].backend_out);
            for mt in sent {
                self.m[1 - i].backend_event(DriverEvent::Received(mt));
            }
        }
        for i in 0..2 {
            self.said[i].extend(std::mem::take(&mut self.m[i].out));
        }
    }

    /// Runs both modems for `d`, answering every `$CADRQ` with `data`.
    async fn run(&mut self, d: Duration, data: &[&str]) {
        let end = Instant::now() + d;
        let mut seen = [0usize; 2];
        while Instant::now() < end {
            tokio::time::advance(Duration::from_millis(10)).await;
            let now = Instant::now();
            for m in &mut self.m {
                m.timers(now);
            }
            self.collect();
            for (i, seen) in seen.iter_mut().enumerate() {
                let new: Vec<NmeaSentence> = self.said[i][*seen..].to_vec();
                *seen = self.said[i].len();
                for s in new {
                    if s.address() == "CADRQ" {
                        let frame: usize = s.field(5).unwrap().parse().unwrap();
                        let (src, dest, ack) = (
                            s.field(1).unwrap(),
                            s.field(2).unwrap(),
                            s.field(3).unwrap(),
                        );
                        let hex = data.get(frame - 1).copied().unwrap_or("");
                        self.host(i, &format!("CCTXD,{src},{dest},{ack},{hex}"));
                    }
                }
            }
        }
    }

    fn addresses(&self, i: usize) -> Vec<String> {
        self.said[i].iter().map(NmeaSentence::address).collect()
    }

    fn take(&mut self, i: usize) -> Vec<NmeaSentence> {
        std::mem::take(&mut self.said[i])
    }
}

/// A host that behaves as Goby3's Micro-Modem driver with `CST` on: a
/// reception (`$CACYC` from another modem, its `$CARXD`s) or an ack
/// (`$CAACK`) is handed up only at the `$CACST` that closes it, two
/// `$CACST`s for a rate-0 cycle (the cycle initialization's and the data's),
/// one otherwise.
#[derive(Default)]
struct StatsGatedHost {
    me: u32,
    /// This host started the cycle under way (`$CCCYC`), e.g. a poll.
    local_cycle: bool,
    frames: Vec<String>,
    acked: Vec<u32>,
    remaining_cst: u32,
    delivered: Vec<String>,
    acks: Vec<u32>,
}

impl StatsGatedHost {
    fn new(me: u32) -> Self {
        StatsGatedHost {
            me,
            ..Default::default()
        }
    }

    fn read(&mut self, lines: &[NmeaSentence]) {
        for s in lines {
            let f = |i: usize| s.field(i).unwrap_or("").to_string();
            match s.address().as_str() {
                "CACYC" if f(1).parse::<u32>().ok() == Some(self.me) => self.local_cycle = false,
                "CACYC" => {
                    let rate0 = f(3) == "0";
                    if self.local_cycle && !rate0 {
                        // A poll at rates above 0 is announced twice: by its
                        // echo and by the data; the echo is passed over.
                        self.local_cycle = false;
                        continue;
                    }
                    self.frames.clear();
                    // At rate 0 the cycle initialization has its own
                    // $CACST, unless this host sent it (a poll).
                    self.remaining_cst = u32::from(rate0 && !self.local_cycle);
                    self.local_cycle = false;
                }
                "CARXD" if !f(4).is_empty() => self.frames.push(f(4)),
                "CAACK" if f(1).parse::<u32>().ok() == Some(self.me) => {
                    self.acked.push(f(2).parse().unwrap())
                }
                "CACST" => {
                    if self.remaining_cst > 0 {
                        self.remaining_cst -= 1;
                    } else {
                        self.delivered.append(&mut self.frames);
                        self.acks.append(&mut self.acked);
                    }
                }
                _ => {}
            }
        }
    }
}

/// Both dialects, rates 0 and 1: every packet heard, data and ack, is
/// closed by a `$CACST`, so a host that waits for it hands everything up.
#[tokio::test(start_paused = true)]
async fn with_cst_on_every_reception_and_ack_ends_with_its_statistics() {
    for dialect in [Dialect::MicroModem1, Dialect::MicroModem2] {
        for rate in [0u32, 1] {
            let mut p = Pair::new(config(dialect, 1), config(dialect, 2));
            let mut hosts = [StatsGatedHost::new(1), StatsGatedHost::new(2)];
            for (i, (src, dest)) in [(1, 2), (2, 1)].into_iter().enumerate() {
                p.host(i, &format!("CCCYC,0,{src},{dest},{rate},1,1"));
                p.run(Duration::from_secs(8), &["C0FFEE"]).await;
                for (h, host) in hosts.iter_mut().enumerate() {
                    host.read(&p.take(h));
                }
            }
            let what = format!("{dialect:?} rate {rate}");
            assert_eq!(hosts[1].delivered, ["C0FFEE"], "{what}: 1 to 2");
            assert_eq!(hosts[0].delivered, ["C0FFEE"], "{what}: 2 to 1");
            assert_eq!(hosts[0].acks, [1], "{what}: 2 acked 1's frame");
            assert_eq!(hosts[1].acks, [1], "{what}: 1 acked 2's frame");
        }
    }
}

#[tokio::test(start_paused = true)]
async fn a_micromodem1_rate0_cycle_starts_with_its_cycle_initialization() {
    let mut p = Pair::new(
        config(Dialect::MicroModem1, 1),
        config(Dialect::MicroModem1, 2),
    );
    p.host(0, "CCCYC,0,1,2,0,1,1");
    p.run(Duration::from_secs(6), &["48454C4C4F"]).await;
    assert_eq!(
        p.addresses(0),
        [
            "CACYC", "CATXP", "CATXF", "CAXST", "CADRQ", "CATXD", "CATXP", "CATXF", "CAXST",
            "CAACK", "CACST"
        ]
    );
    assert_eq!(
        p.addresses(1),
        ["CACYC", "CACST", "CARXD", "CACST", "CATXP", "CATXF", "CAXST"]
    );
    let said = p.take(1);
    assert_eq!(body(&said[0]), "CACYC,0,1,2,0,1,1");
    // Version 6, as Micro-Modem 1 firmware 0.93.0.52 and later write it:
    // the cycle initialization is an FSK mini-packet, the data FSK.
    for (s, packet_type) in [(&said[1], "2"), (&said[3], "1")] {
        assert_eq!(s.fields.len(), 30, "{s}");
        assert_eq!(s.field(0), Some("6"), "{s}");
        assert_eq!(s.field(17), Some(packet_type), "{s}");
        assert_eq!(s.field(3), Some("00"), "clock mode: never set: {s}");
    }
    assert_eq!(body(&said[2]), "CARXD,1,2,1,1,48454C4C4F");
}

#[tokio::test(start_paused = true)]
async fn statistics_follow_the_nvram_and_the_firmware() {
    // XST off, CST on at the sender; CST off at the receiver.
    let mut p = Pair::new(
        config(Dialect::MicroModem2, 1),
        config(Dialect::MicroModem2, 2),
    );
    p.host(0, "CCCFG,XST,0");
    p.host(1, "CCCFG,CST,0");
    p.take(0);
    p.take(1);
    p.host(0, "CCCYC,0,1,2,1,1,1");
    p.run(Duration::from_secs(10), &["0102"]).await;
    assert!(
        !p.addresses(0).contains(&"CAXST".to_string()),
        "{:?}",
        p.addresses(0)
    );
    assert!(
        p.addresses(0).contains(&"CACST".to_string()),
        "the ack's: {:?}",
        p.addresses(0)
    );
    assert!(
        !p.addresses(1).contains(&"CACST".to_string()),
        "{:?}",
        p.addresses(1)
    );
    assert!(p.addresses(1).contains(&"CAXST".to_string()), "the ack's");

    // Firmware 3.x writes $CACST version 8 and $CAXST version 7; a layout
    // configured wins over the firmware's.
    let v3 = |id| EmulatorConfig {
        version: "3.9.4".into(),
        ..config(Dialect::MicroModem2, id)
    };
    let legacy = EmulatorConfig {
        stats_layout: Some(StatsLayout::Legacy),
        ..config(Dialect::MicroModem1, 2)
    };
    for (b, cst_fields, xst_fields) in [(v3(2), 34, 17), (legacy, 29, 15)] {
        let mut p = Pair::new(v3(1), b);
        p.host(0, "CCCYC,0,1,2,1,1,1");
        p.run(Duration::from_secs(10), &["0102"]).await;
        let said = p.take(1);
        let cst = said.iter().find(|s| s.address() == "CACST").unwrap();
        let xst = said.iter().find(|s| s.address() == "CAXST").unwrap();
        assert_eq!(
            (cst.fields.len(), xst.fields.len()),
            (cst_fields, xst_fields),
            "{cst} {xst}"
        );
    }
}

#[tokio::test(start_paused = true)]
async fn sleep_command_echoes_then_reboots() {
    for dialect in [Dialect::MicroModem1, Dialect::MicroModem2] {
        let mut m = modem(config(dialect, 3));
        m.line(&line("CCMSC,3,3,0"), true);
        assert_eq!(body(&m.out.remove(0)), "CAMSC,3,3,0");
        assert!(m.out.is_empty());
        // Rebooting: deaf and mute.
        m.line(&line("CCCFQ,SRC"), true);
        assert!(m.out.is_empty());
        assert!(!m.revision_enabled());
        tokio::time::advance(m.config.boot_time).await;
        m.timers(Instant::now());
        let rev = m.out.remove(0);
        assert_eq!(rev.address(), "CAREV");
        assert_eq!(rev.field(1), Some("INIT"), "{rev}");
        assert!(m.revision_enabled());
        m.out.clear();
        // The NVRAM survives the reboot.
        m.line(&line("CCCFQ,SRC"), true);
        assert_eq!(body(&m.out.remove(0)), "CACFG,SRC,3");
        assert_eq!(m.ignored.lock().unwrap().len(), 1, "{dialect:?}");
    }

    let mut m = modem(config(Dialect::MicroModem1, 3));
    // Until woken: the next host line wakes it, unread.
    m.line(&line("CCMSC,3,3,-1"), true);
    assert_eq!(body(&m.out.remove(0)), "CAMSC,3,3,-1");
    tokio::time::advance(Duration::from_secs(3600)).await;
    m.timers(Instant::now());
    assert!(m.out.is_empty());
    m.line(&line("CCCFQ,SRC"), true);
    assert_eq!(m.out.remove(0).field(1), Some("INIT"));
    // Minutes: asleep that long.
    m.out.clear();
    m.line(&line("CCMSC,3,3,2"), true);
    m.out.clear();
    tokio::time::advance(Duration::from_secs(119)).await;
    m.timers(Instant::now());
    assert!(m.out.is_empty());
    tokio::time::advance(Duration::from_secs(1)).await;
    m.timers(Instant::now());
    assert_eq!(m.out.remove(0).field(1), Some("INIT"));
    // Another modem, or a field that is no number: refused, named.
    m.out.clear();
    m.line(&line("CCMSC,3,4,0"), true);
    let err = m.out.remove(0);
    assert_eq!(err.address(), "CAERR");
    assert!(err.field(3).unwrap().contains("field 1 (dest)"), "{err}");
    m.line(&line("CCMSC,3,3,soon"), true);
    assert!(m
        .out
        .remove(0)
        .field(3)
        .unwrap()
        .contains("field 2 (minutes)"));
    assert!(m.revision_enabled());
}

#[tokio::test(start_paused = true)]
async fn nvram_revision_messages_and_the_clock() {
    let mut m = modem(config(Dialect::MicroModem1, 4));
    // Factory settings: statistics and revision messages on.
    for key in ["CST", "XST", "REV"] {
        m.line(&line(&format!("CCCFQ,{key}")), true);
        assert_eq!(body(&m.out.remove(0)), format!("CACFG,{key},1"));
    }
    m.line(&line("CCCFG,REV,0"), true);
    assert_eq!(body(&m.out.remove(0)), "CACFG,REV,0");
    assert!(!m.revision_enabled());
    // Back to the factory: REV on again, the id kept, no parameter "ALL".
    m.line(&line("CCCFG,ALL,0"), true);
    assert_eq!(body(&m.out.remove(0)), "CACFG,ALL,0");
    assert!(m.revision_enabled());
    assert!(!m.settings.contains_key("ALL"));
    m.line(&line("CCCFQ,ALL"), true);
    let all: Vec<String> = m.out.drain(..).map(|s| body(&s)).collect();
    assert!(all.contains(&"CACFG,SRC,4".to_string()), "{all:?}");
    assert!(
        all.len() > 60 && all.iter().all(|l| !l.contains('.')),
        "{all:?}"
    );
    m.line(&line("CCCFQ,NOPE"), true);
    assert_eq!(m.out.remove(0).address(), "CAERR");

    // $CCCLK sets a Micro-Modem 1's clock too.
    m.line(&line("CCCLK,2030,1,2,3,4,5"), true);
    assert_eq!(body(&m.out.remove(0)), "CACLK,2030,01,02,03,04,05");
    assert!(m.out.is_empty(), "no $CATMG from a Micro-Modem 1");
    let t = m.clock() / 1_000_000;
    assert!((1_893_553_445..1_893_553_450).contains(&t), "{t}");
}

#[tokio::test(start_paused = true)]
async fn a_poll_asks_the_other_modem_for_its_data() {
    for (dialect, rate) in [(Dialect::MicroModem1, 1u32), (Dialect::MicroModem2, 0)] {
        let mut p = Pair::new(config(dialect, 1), config(dialect, 2));
        let mut hosts = [StatsGatedHost::new(1), StatsGatedHost::new(2)];
        // Modem 1 polls modem 2 for one frame, to modem 1.
        hosts[0].local_cycle = true;
        p.host(0, &format!("CCCYC,0,2,1,{rate},1,1"));
        p.run(Duration::from_secs(8), &["ABCD"]).await;
        let what = format!("{dialect:?} rate {rate}");
        let first = |said: &[NmeaSentence], address: &str| {
            said.iter()
                .find(|s| s.address() == address)
                .map(body)
                .unwrap_or_else(|| panic!("{what}: no {address}"))
        };
        assert_eq!(
            first(&p.said[0], "CACYC"),
            format!("CACYC,0,2,1,{rate},1,1")
        );
        // The polled modem runs the cycle its host did not start.
        assert_eq!(
            first(&p.said[1], "CACYC"),
            format!("CACYC,0,2,1,{rate},1,1")
        );
        assert!(p.addresses(1).contains(&"CADRQ".to_string()), "{what}");
        assert!(
            p.said[0].iter().any(|s| body(s) == "CARXD,2,1,1,1,ABCD"),
            "{what}: {:?}",
            p.addresses(0)
        );
        hosts[0].read(&p.take(0));
        hosts[1].read(&p.take(1));
        assert_eq!(hosts[0].delivered, ["ABCD"], "{what}");
        assert_eq!(hosts[1].acks, [1], "{what}");
    }
}

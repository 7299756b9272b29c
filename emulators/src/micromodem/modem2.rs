//! What only an emulated Micro-Modem 2 does: its clock commands (`$CCTMS`,
//! `$CCTMQ`), its paced configuration echo (`$CCCFQ,ALL` / `TOP`, during
//! which host commands are ignored) and Flexible Data Protocol packets.
//!
//! `$CCCLK` is still answered (with `$CACLK`) rather than refused: Goby3's
//! driver sends it to any modem whose `$CAREV,…,AUV` it has not seen yet,
//! which at start-up includes a Micro-Modem 2, and expects `$CACLK` back;
//! once it knows the version it uses `$CCTMS`.

use std::time::Duration;

use protos::goby::acomms::protobuf::{micro_modem_emulated_packet::Kind, MicroModemEmulatedPacket};
use tokio::time::Instant;

use super::common::{config_line, Timer};
use super::mm2::{self, FdpRequest};
use super::modem::{wrap, Echo, Modem, WaterKind};
use super::nvram;
use super::stats::PacketType;
use modemdriver::micromodem::nmea::NmeaSentence;
use modemdriver::micromodem::sentence::{Cycle, MmSentence};
use modemdriver::rate;
use modemdriver::time::now_micros;

/// How long an external-pulse clock setting waits before it gives up.
const EXTERNAL_PULSE_TIMEOUT: Duration = Duration::from_secs(3);
/// How long the modem takes to answer `$CCTMQ`.
const TIME_QUERY_DELAY: Duration = Duration::from_millis(500);

/// State only a Micro-Modem 2 has.
#[derive(Debug)]
pub(super) struct Mm2State {
    /// Configuration echo still to write, one line per interval.
    echo: Echo,
    echo_next: Instant,
    fdp_id: u32,
}

impl Mm2State {
    pub(super) fn new() -> Self {
        Mm2State {
            echo: Echo::new(),
            echo_next: Instant::now(),
            fdp_id: 0,
        }
    }

    /// After a reset: the echo under way is forgotten.
    pub(super) fn restart(&mut self) {
        self.echo.clear();
    }

    pub(super) fn next_deadline(&self) -> Option<Instant> {
        (!self.echo.is_empty()).then_some(self.echo_next)
    }
}

impl Modem {
    /// While the configuration echo runs, host commands are ignored (as a
    /// real Micro-Modem 2 ignores them): recorded, not answered.
    pub(super) fn mm2_busy(&mut self, nmea: &NmeaSentence) -> bool {
        let busy = self.mm2.as_ref().is_some_and(|m| !m.echo.is_empty());
        if busy {
            self.ignore(nmea.to_string());
        }
        busy
    }

    /// Handles what only a Micro-Modem 2 answers; `false` leaves the
    /// sentence to the common handling.
    pub(super) fn mm2_line(&mut self, nmea: &NmeaSentence) -> bool {
        if nmea.talker != "CC" {
            return false;
        }
        match nmea.id.as_str() {
            "TMS" => match mm2::parse_set_clock(nmea) {
                Ok(set) if set.mode == 0 => {
                    // Takes effect at the modem's next whole second.
                    let now = now_micros();
                    let wait = 1_000_000 - now % 1_000_000;
                    self.schedule(
                        Instant::now() + Duration::from_micros(wait),
                        Timer::ClockSet {
                            time: set.time,
                            timed_out: false,
                        },
                    );
                }
                Ok(set) => self.schedule(
                    Instant::now() + EXTERNAL_PULSE_TIMEOUT,
                    Timer::ClockSet {
                        time: set.time,
                        timed_out: true,
                    },
                ),
                Err(e) => self.error("NMEA", "3", e),
            },
            "TMQ" => {
                let time = self.clock();
                self.schedule(Instant::now() + TIME_QUERY_DELAY, Timer::TimeQuery { time });
            }
            "CFQ" => {
                // ALL or TOP (the common handling answers single keys).
                let key = nmea.field(0).unwrap_or("").trim().to_string();
                let interval = self.config.config_line_interval;
                let lines: Vec<NmeaSentence> = self
                    .settings
                    .iter()
                    .filter(|(k, _)| key == "ALL" || nvram::is_top_level(k))
                    .map(|(k, v)| config_line(k, v))
                    .collect();
                if let Some(m) = &mut self.mm2 {
                    m.echo.extend(lines);
                    m.echo_next = Instant::now() + interval;
                }
            }
            "TDP" => self.flexible_data(nmea),
            _ => return false,
        }
        true
    }

    /// Writes the next line of the configuration echo when it is due.
    pub(super) fn mm2_timers(&mut self, now: Instant) {
        let Some(m) = &mut self.mm2 else { return };
        if !m.echo.is_empty() && m.echo_next <= now {
            if let Some(line) = m.echo.pop_front() {
                self.out.push(line);
            }
            m.echo_next = now + self.config.config_line_interval;
        }
    }

    fn flexible_data(&mut self, nmea: &NmeaSentence) {
        let field = |i: usize| {
            nmea.field(i)
                .and_then(|v| v.parse::<u32>().ok())
                .unwrap_or(0)
        };
        let (dest, rate, ack) = (field(0), field(1), field(2) != 0);
        let id = match &mut self.mm2 {
            Some(m) => {
                m.fdp_id += 1;
                m.fdp_id
            }
            None => return,
        };
        match mm2::parse_fdp(nmea) {
            Ok(request) => {
                let bytes = request.data.len();
                self.out
                    .push(mm2::fdp_echo(false, id, dest, rate, ack, bytes));
                self.schedule_after_tx_delay(Timer::SendFdp(request));
            }
            Err(e) => {
                self.out.push(mm2::fdp_echo(true, id, dest, rate, ack, 0));
                self.error("TDP", "1", e);
            }
        }
    }

    pub(super) fn send_fdp(&mut self, request: FdpRequest) {
        let me = self.id();
        let bytes = request.data.len() as u32;
        let frames = mm2::fdp_frames(request.rate, request.data.len()) as u32;
        self.say(MmSentence::TransmitStart { bytes });
        let bits_per_second = rate::spec(request.rate as i32).map_or(250.0, |s| s.bits_per_second);
        let duration = self.config.packet_overhead
            + Duration::from_secs_f64(f64::from(bytes * 8) / bits_per_second);
        let cycle = Cycle {
            src: me,
            dest: request.dest,
            rate: request.rate,
            ack: request.ack,
            frames,
        };
        let xst = self.transmit_stats(cycle, frames, PacketType::FlexibleData, bytes);
        let packet = MicroModemEmulatedPacket {
            kind: Kind::Fdp as i32,
            rate: Some(request.rate),
            ack_requested: Some(request.ack),
            frame: vec![request.data],
            ..Default::default()
        };
        self.transmit(
            wrap(me, request.dest, packet),
            duration,
            WaterKind::FlexibleData,
            bytes,
            Some(xst),
        );
    }

    /// A Flexible Data Protocol packet heard (a Micro-Modem 1 does not know
    /// them): `$CARDP`, each frame failing its CRC by the same faults as
    /// data, then `$CACST`.
    pub(super) fn receive_fdp(&mut self, src: u32, dest: u32, packet: &MicroModemEmulatedPacket) {
        if self.mm2.is_none() {
            return;
        }
        let data = packet.frame.first().cloned().unwrap_or_default();
        let frames = mm2::fdp_frames(packet.rate(), data.len());
        let mut bad = Vec::new();
        for i in 0..frames {
            let bad_crc = self.config.faults.bad_crc;
            if self.draw(|m| &mut m.bad_crc_next, bad_crc) {
                bad.push(i);
            }
        }
        self.out.push(mm2::fdp_received(
            src,
            dest,
            packet.rate(),
            packet.ack_requested(),
            &data,
            &bad,
        ));
        self.receive_stats(
            src,
            dest,
            packet.rate(),
            PacketType::FlexibleData,
            frames as u32,
            bad.len() as u32,
        );
    }
}

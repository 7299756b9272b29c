//! What only an emulated Micro-Modem 2 does: its clock commands, its paced
//! configuration echo (during which host commands are ignored), the
//! cycle-initialization packet of a rate-0 cycle, the transmit delay,
//! statistics after each packet, Flexible Data Protocol packets and
//! long-baseline ranging.
//!
//! `$CCCLK` is still answered (with `$CACLK`) rather than refused: Goby3's
//! driver sends it to any modem whose `$CAREV,…,AUV` it has not seen yet,
//! which at start-up includes a Micro-Modem 2, and expects `$CACLK` back;
//! once it knows the version it uses `$CCTMS`.

use std::time::Duration;

use protos::goby::acomms::protobuf::{micro_modem_emulated_packet::Kind, MicroModemEmulatedPacket};
use tokio::time::Instant;

use super::geometry::{self, DEFAULT_RANGE_M};
use super::mm2::{self, ClockSource, FdpRequest, Interrogation, LblRequest};
use super::modem::{wrap, Echo, Modem, WaterKind};
use super::nvram;
use super::stats::{PacketType, ReceiveStats};
use crate::micromodem::nmea::NmeaSentence;
use crate::micromodem::sentence::{Cycle, MmSentence};
use crate::rate;
use crate::time::now_micros;

/// How long an external-pulse clock setting waits before it gives up.
const EXTERNAL_PULSE_TIMEOUT: Duration = Duration::from_secs(3);
/// How long the modem takes to answer `$CCTMQ`.
const TIME_QUERY_DELAY: Duration = Duration::from_millis(500);

/// Something a Micro-Modem 2 does later.
#[derive(Debug, Clone)]
pub(super) enum Timer {
    /// Set the clock to `time` (or give up waiting for the pulse).
    ClockSet { time: u64, timed_out: bool },
    /// Answer a time query with the time it was asked at.
    TimeQuery { time: u64 },
    /// Put the rate-0 cycle-initialization packet on the water.
    SendInit,
    /// Put the assembled data packet on the water.
    SendData,
    /// Put a Flexible Data Protocol packet on the water.
    SendFdp(FdpRequest),
    /// Report the travel times of an interrogation.
    TravelTimes {
        times: [Option<f64>; 4],
        ping_time: u64,
    },
}

/// State only a Micro-Modem 2 has.
#[derive(Debug)]
pub(super) struct Mm2State {
    /// Configuration echo still to write, one line per interval.
    echo: Echo,
    echo_next: Instant,
    /// Modem clock minus host clock, µs.
    pub(super) clock_offset: i64,
    pub(super) clock_source: ClockSource,
    timers: Vec<(Instant, Timer)>,
    fdp_id: u32,
    /// Sender of the last rate-0 cycle-initialization packet heard.
    announced_by: Option<u32>,
}

impl Mm2State {
    pub(super) fn new() -> Self {
        Mm2State {
            echo: Echo::new(),
            echo_next: Instant::now(),
            clock_offset: 0,
            clock_source: ClockSource::Rtc,
            timers: Vec::new(),
            fdp_id: 0,
            announced_by: None,
        }
    }

    /// After a reset: what was under way is forgotten; the clock runs on
    /// but counts as unset.
    pub(super) fn restart(&mut self) {
        self.echo.clear();
        self.timers.clear();
        self.announced_by = None;
        self.clock_source = ClockSource::Rtc;
    }

    pub(super) fn next_deadline(&self) -> Option<Instant> {
        let echo = (!self.echo.is_empty()).then_some(self.echo_next);
        self.timers.iter().map(|(t, _)| *t).chain(echo).min()
    }
}

impl Modem {
    fn setting_u32(&self, key: &str) -> u32 {
        self.settings
            .get(key)
            .and_then(|v| v.parse().ok())
            .unwrap_or(0)
    }

    fn schedule(&mut self, at: Instant, timer: Timer) {
        if let Some(m) = &mut self.mm2 {
            m.timers.push((at, timer));
        }
    }

    /// Schedules `timer` after the transmit delay (NVRAM `TXD`, ms).
    pub(super) fn schedule_after_tx_delay(&mut self, timer: Timer) {
        let delay = Duration::from_millis(u64::from(self.setting_u32("TXD")));
        self.schedule(Instant::now() + delay, timer);
    }

    /// The cycle waits on the modem, not on the host: no data timeout.
    pub(super) fn hold_cycle(&mut self) {
        if let Some(tx) = &mut self.tx {
            tx.deadline = Instant::now() + Duration::from_secs(3600);
        }
    }

    /// While the configuration echo runs, host commands are ignored (as a
    /// real Micro-Modem 2 ignores them): recorded, not answered.
    pub(super) fn mm2_busy(&mut self, nmea: &NmeaSentence) -> bool {
        let busy = self.mm2.as_ref().is_some_and(|m| !m.echo.is_empty());
        if busy {
            self.ignore(nmea.to_string());
        }
        busy
    }

    /// Handles what a Micro-Modem 2 answers differently; `false` leaves the
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
            "CLK" => match MmSentence::from_nmea(nmea) {
                Ok(MmSentence::Clock { date_time, .. }) => {
                    // Still understood (the older command): set to the second.
                    let [y, mo, d, h, mi, s] = date_time;
                    let iso = format!("{y:04}-{mo:02}-{d:02}T{h:02}:{mi:02}:{s:02}Z");
                    match mm2::parse_iso(&iso) {
                        Some(t) => {
                            self.set_clock(t);
                            self.say(MmSentence::Clock {
                                from_modem: true,
                                date_time,
                            });
                            self.clock_source_changed();
                        }
                        None => self.error("NMEA", "3", format!("$CCCLK: {iso} is no date")),
                    }
                }
                Ok(_) => {}
                Err(e) => self.error("NMEA", "3", e.to_string()),
            },
            "CFQ" => {
                let key = nmea.field(0).unwrap_or("").to_string();
                let interval = self.config.config_line_interval;
                match key.as_str() {
                    "ALL" | "TOP" => {
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
                    _ => match self.settings.get(&key).cloned() {
                        Some(v) => self.out.push(config_line(&key, &v)),
                        None => self.error("CFG", "2", format!("unknown parameter {key}")),
                    },
                }
            }
            "CFG" => {
                let key = nmea.field(0).unwrap_or("").to_string();
                let value = nmea.field(1).unwrap_or("").to_string();
                if key.is_empty() {
                    self.error("NMEA", "3", "$CCCFG field 0 (key): missing");
                    return true;
                }
                if key == "ALL" {
                    let id = self.id().to_string();
                    self.settings.clear();
                    self.settings
                        .extend(nvram::micromodem2(self.config.modem_id));
                    self.settings.insert("SRC".into(), id);
                } else {
                    self.settings.insert(key.clone(), value.clone());
                }
                self.out.push(config_line(&key, &value));
            }
            "TDP" => self.flexible_data(nmea),
            "PDT" | "PNT" => self.interrogate(nmea),
            _ => return false,
        }
        true
    }

    fn set_clock(&mut self, time: u64) {
        if let Some(m) = &mut self.mm2 {
            m.clock_offset = i64::try_from(time).unwrap_or(i64::MAX)
                - i64::try_from(now_micros()).unwrap_or(i64::MAX);
        }
    }

    /// The clock now counts as set by the host: `$CATMG` if that is new.
    fn clock_source_changed(&mut self) {
        let Some(m) = &mut self.mm2 else { return };
        if m.clock_source != ClockSource::UserCommand {
            m.clock_source = ClockSource::UserCommand;
            let now = self.clock();
            self.out
                .push(mm2::timing(false, now, ClockSource::UserCommand));
        }
    }

    pub(super) fn mm2_timers(&mut self, now: Instant) {
        let Some(m) = &mut self.mm2 else { return };
        if !m.echo.is_empty() && m.echo_next <= now {
            if let Some(line) = m.echo.pop_front() {
                self.out.push(line);
            }
            m.echo_next = now + self.config.config_line_interval;
        }
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut m.timers)
            .into_iter()
            .partition(|(t, _)| *t <= now);
        m.timers = later;
        // One packet on the water at a time: a transmission waits for the
        // one under way.
        let water_clear = self.on_water.iter().map(|p| p.ends).max();
        for (_, timer) in due {
            if let (Some(clear), Timer::SendInit | Timer::SendData | Timer::SendFdp(_)) =
                (water_clear, &timer)
            {
                if clear > now {
                    self.schedule(clear, timer);
                    continue;
                }
            }
            match timer {
                Timer::ClockSet {
                    time,
                    timed_out: false,
                } => {
                    self.set_clock(time);
                    self.out.push(mm2::set_clock_reply(false, time));
                    self.clock_source_changed();
                }
                Timer::ClockSet {
                    timed_out: true, ..
                } => {
                    let now = self.clock();
                    self.out.push(mm2::set_clock_reply(true, now));
                }
                Timer::TimeQuery { time } => {
                    let source = self
                        .mm2
                        .as_ref()
                        .map_or(ClockSource::Rtc, |m| m.clock_source);
                    self.out.push(mm2::timing(true, time, source));
                }
                Timer::SendInit => self.send_init(),
                Timer::SendData => self.send_cycle(true),
                Timer::SendFdp(request) => self.send_fdp(request),
                Timer::TravelTimes { times, ping_time } => {
                    self.out.push(mm2::travel_times(times, ping_time));
                }
            }
        }
    }

    /// The rate-0 cycle-initialization packet: `$CATXP`, on the water, then
    /// `$CATXF` and `$CAXST`, and only then `$CADRQ` for the data.
    fn send_init(&mut self) {
        let Some(tx) = &self.tx else { return };
        let cycle = tx.cycle;
        self.say(MmSentence::TransmitStart { bytes: 0 });
        let packet = MicroModemEmulatedPacket {
            kind: Kind::CycleInit as i32,
            rate: Some(cycle.rate),
            ack_requested: Some(cycle.ack),
            frame_count: Some(cycle.frames),
            ..Default::default()
        };
        let xst = self.transmit_stats(cycle, 1, PacketType::FskMini, 0);
        self.transmit(
            wrap(cycle.src, cycle.dest, packet),
            self.config.packet_overhead,
            WaterKind::CycleInit,
            0,
            Some(xst),
        );
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

    fn send_fdp(&mut self, request: FdpRequest) {
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

    fn interrogate(&mut self, nmea: &NmeaSentence) {
        let request = match mm2::parse_lbl(nmea) {
            Ok(r) => r,
            Err(e) => return self.error("NMEA", "3", e),
        };
        self.out.push(mm2::lbl_echo(nmea));
        let times = self.travel_times(&request);
        let ping_time = self.clock();
        self.schedule(
            Instant::now() + Duration::from_millis(u64::from(request.timeout_ms)),
            Timer::TravelTimes { times, ping_time },
        );
    }

    /// One-way travel times (s) to transponders A-D whose replies arrive
    /// within the timeout (the round trip plus their turn-around time,
    /// NVRAM `TAT`, ms); reported as the modem does, half the round trip
    /// with the turn-around taken out.
    fn travel_times(&self, request: &LblRequest) -> [Option<f64>; 4] {
        let g = &self.config.geometry;
        let me = self.id();
        let turnaround = f64::from(self.setting_u32("TAT")) / 1000.0;
        let timeout = f64::from(request.timeout_ms) / 1000.0;
        let mut times = [None; 4];
        for (slot, time) in times.iter_mut().enumerate() {
            let transponder = match request.interrogation {
                Interrogation::Remus(enabled) => {
                    enabled[slot].then(|| g.transponders.get(slot)).flatten()
                }
                Interrogation::Narrowband(freqs) if freqs[slot] != 0 => g
                    .transponders
                    .iter()
                    .find(|t| t.frequency == Some(freqs[slot]))
                    .or_else(|| g.transponders.get(slot).filter(|t| t.frequency.is_none())),
                Interrogation::Narrowband(_) => None,
            };
            *time = transponder
                .and_then(|t| g.round_trip(me, t))
                .filter(|t| t + turnaround <= timeout)
                .map(|round_trip| round_trip / 2.0);
        }
        times
    }

    /// A Micro-Modem 2 reports `$CAXST` for a ping, ping reply or
    /// mini-packet the backend sent.
    pub(super) fn mm2_sent_special(
        &mut self,
        mt: &protos::goby::acomms::protobuf::ModemTransmission,
        packet: &MicroModemEmulatedPacket,
    ) {
        if self.mm2.is_none() || !matches!(packet.kind(), Kind::Ping | Kind::PingReply | Kind::Mini)
        {
            return;
        }
        let cycle = Cycle {
            src: mt.src().max(0) as u32,
            dest: mt.dest().max(0) as u32,
            rate: 0,
            ack: false,
            frames: 1,
        };
        let bytes = if packet.kind() == Kind::Mini { 2 } else { 0 };
        let xst = self.transmit_stats(cycle, 1, PacketType::FskMini, bytes);
        let layout = self.config.stats_layout;
        self.out.push(xst.to_nmea(layout));
    }

    /// Whether a rate-0 data packet from `src` was announced by its
    /// cycle-initialization packet (then its `$CACYC` was already reported).
    pub(super) fn mm2_take_announced(&mut self, src: u32, rate: u32) -> bool {
        match &mut self.mm2 {
            Some(m) if rate == 0 && m.announced_by == Some(src) => {
                m.announced_by = None;
                true
            }
            _ => false,
        }
    }

    /// A rate-0 cycle-initialization packet heard: `$CACYC` (and `$CACST`).
    pub(super) fn receive_cycle_init(
        &mut self,
        src: u32,
        dest: u32,
        packet: &MicroModemEmulatedPacket,
    ) {
        self.say(MmSentence::Cycle {
            from_modem: true,
            cycle: Cycle {
                src,
                dest,
                rate: packet.rate(),
                ack: packet.ack_requested(),
                frames: packet.frame_count(),
            },
        });
        if let Some(m) = &mut self.mm2 {
            m.announced_by = Some(src);
        }
        self.mm2_receive_stats(src, dest, packet.rate(), PacketType::FskMini, 1, 0);
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
        self.mm2_receive_stats(
            src,
            dest,
            packet.rate(),
            PacketType::FlexibleData,
            frames as u32,
            bad.len() as u32,
        );
    }

    /// `$CACST` of a packet from `src`, from the simulated link.
    pub(super) fn mm2_receive_stats(
        &mut self,
        src: u32,
        dest: u32,
        rate: u32,
        packet_type: PacketType,
        frames: u32,
        bad_frames: u32,
    ) {
        let Some(m) = &self.mm2 else { return };
        let stats = link_stats(
            self,
            m.clock_source,
            LinkPacket {
                src,
                dest,
                rate,
                packet_type,
                frames,
                bad_frames,
            },
        );
        let layout = self.config.stats_layout;
        self.out.push(stats.to_nmea(layout));
    }
}

/// What a reception was.
struct LinkPacket {
    src: u32,
    dest: u32,
    rate: u32,
    packet_type: PacketType,
    frames: u32,
    bad_frames: u32,
}

/// Receive statistics from the geometry: SNR from the range (or the lone
/// range, or [`DEFAULT_RANGE_M`]), Doppler from the nodes' velocities.
fn link_stats(modem: &Modem, source: ClockSource, p: LinkPacket) -> ReceiveStats {
    let g = &modem.config.geometry;
    let me = modem.id();
    let range = g
        .range(p.src, me)
        .or(modem.config.lone_range)
        .unwrap_or(DEFAULT_RANGE_M);
    let snr = geometry::snr_db(range);
    let level = geometry::received_level_db(range);
    let fsk = matches!(p.packet_type, PacketType::Fsk | PacketType::FskMini);
    let duration = match p.packet_type {
        PacketType::Fsk | PacketType::Psk => rate::spec(p.rate as i32)
            .map_or(modem.config.packet_overhead, |s| {
                s.packet_duration(modem.config.packet_overhead)
            }),
        _ => modem.config.packet_overhead,
    };
    let toa = modem
        .clock()
        .saturating_sub(u64::try_from(duration.as_micros()).unwrap_or(0));
    // The equalizer's output SNR saturates near 20 dB.
    let snr_out = 20.0 * (snr / 20.0).tanh();
    let round = |v: f64| v.round() as i32;
    ReceiveStats {
        mode: u32::from(p.bad_frames > 0),
        toa,
        clock_mode: source.receive_clock_bits(),
        mfd_peak: round((100.0 * 10f64.powf(snr / 20.0)).clamp(0.0, 32767.0)),
        mfd_power: round(level - geometry::noise_level_db()),
        mfd_ratio: round((10.0 * snr).clamp(0.0, 9999.0)),
        spl: round(level),
        agn: 7,
        rate: p.rate as i32,
        src: p.src,
        dest: p.dest,
        psk_error: if !fsk && p.bad_frames > 0 { 3 } else { 0 },
        packet_type: p.packet_type,
        frames: p.frames,
        bad_frames: p.bad_frames,
        snr_rss: if fsk { -1 } else { round(snr) },
        snr_in: if fsk {
            -1.0
        } else {
            (snr * 10.0).round() / 10.0
        },
        snr_out: if fsk { -1.0 } else { snr_out },
        snr_symbols: if fsk { -1.0 } else { snr_out - 1.0 },
        mse: if fsk { -1.0 } else { -snr_out },
        dqf: if fsk {
            round(255.0 * (1.0 - (-snr.max(0.0) / 10.0).exp()))
        } else {
            -1
        },
        doppler: g.closing_speed(p.src, me),
        noise: round(geometry::noise_level_db() - 36.0),
        carrier: geometry::CARRIER_HZ,
        bandwidth: geometry::BANDWIDTH_HZ,
    }
}

fn config_line(key: &str, value: &str) -> NmeaSentence {
    NmeaSentence::new("CA", "CFG", vec![key.to_string(), value.to_string()])
}

//! What both generations of the emulated modem do besides the cycle itself:
//! the NVRAM (`$CCCFG`, `$CCCFQ`), the clock (`$CCCLK`), sleep and reboot
//! (`$CCMSC`), timers, the rate-0 cycle initialization and polls, the
//! statistics (`$CACST` with NVRAM `CST` on, `$CAXST` with `XST` on, in the
//! layout of the firmware, [`StatsLayout::of_firmware`]) and long-baseline
//! ranging (`$CCPDT`, `$CCPNT`).
//!
//! `$CCMSC,src,dest,minutes` is echoed as `$CAMSC`; then the modem sleeps:
//! 0 minutes reboots at once (for [`EmulatorConfig::boot_time`]), more
//! sleeps that long, -1 sleeps until the host writes again (the line that
//! wakes it is not read). Asleep it hears nothing on the serial line or the
//! water and says nothing; it wakes as from a reboot (`$CAREV,…,INIT`). What
//! was under way when it fell asleep is lost. A `$CCMSC` for another modem
//! (an acoustic sleep command) is refused with `$CAERR`.
//!
//! [`EmulatorConfig::boot_time`]: super::EmulatorConfig::boot_time

use std::time::Duration;

use protos::goby::acomms::protobuf::{
    micro_modem_emulated_packet::Kind, MicroModemEmulatedPacket, ModemTransmission,
};
use tokio::time::Instant;

use super::geometry::{self, DEFAULT_RANGE_M};
use super::mm2::{self, ClockSource, FdpRequest, Interrogation, LblRequest};
use super::modem::{wrap, Modem, TxCycle, WaterKind};
use super::nvram;
use super::stats::{PacketType, ReceiveStats, StatsLayout, TransmitStats};
use super::Dialect;
use modemdriver::micromodem::firmware;
use modemdriver::micromodem::nmea::NmeaSentence;
use modemdriver::micromodem::sentence::{Cycle, MmSentence};
use modemdriver::rate;
use modemdriver::time::now_micros;

/// Something the modem does later.
#[derive(Debug, Clone)]
pub(super) enum Timer {
    /// Set the clock to `time` (or give up waiting for the pulse).
    ClockSet { time: u64, timed_out: bool },
    /// Answer a time query with the time it was asked at.
    TimeQuery { time: u64 },
    /// Put the rate-0 cycle-initialization packet on the water.
    SendInit,
    /// Put a poll of another modem on the water.
    SendPoll(Cycle),
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

/// The modem sleeps (or reboots) until `until`, or with `None` until the
/// host writes.
#[derive(Debug, Clone, Copy)]
pub(super) struct Asleep {
    pub(super) until: Option<Instant>,
}

/// Minutes of `$CCMSC` that mean "until a hardware wake".
const SLEEP_UNTIL_WOKEN: i64 = -1;

impl Modem {
    pub(super) fn setting_u32(&self, key: &str) -> u32 {
        self.settings
            .get(key)
            .and_then(|v| v.trim().parse().ok())
            .unwrap_or(0)
    }

    /// Whether the NVRAM flag `key` (e.g. `CST`) is on.
    pub(super) fn setting_on(&self, key: &str) -> bool {
        self.settings.get(key).is_some_and(|v| {
            let v = v.trim();
            !v.is_empty() && v != "0"
        })
    }

    /// Periodic `$CAREV` (NVRAM `REV`), not while asleep.
    pub fn revision_enabled(&self) -> bool {
        self.asleep.is_none() && self.setting_on("REV")
    }

    /// The layout of `$CACST` / `$CAXST`: as configured, else the one of
    /// the firmware it claims to be.
    pub(super) fn layout(&self) -> StatsLayout {
        self.config
            .stats_layout
            .unwrap_or_else(|| StatsLayout::of_firmware(&self.config.version))
    }

    pub(super) fn schedule(&mut self, at: Instant, timer: Timer) {
        self.timers.push((at, timer));
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

    /// Handles the host commands both generations answer alike; `false`
    /// leaves the sentence to the rest.
    pub(super) fn common_line(&mut self, nmea: &NmeaSentence) -> bool {
        if nmea.talker != "CC" {
            return false;
        }
        match nmea.id.as_str() {
            "CFG" => self.set_config(nmea),
            "CFQ" => {
                let key = nmea.field(0).unwrap_or("").trim().to_string();
                match (self.config.dialect, key.as_str()) {
                    // Paced, one line at a time (see `modem2`).
                    (Dialect::MicroModem2, "ALL" | "TOP") => return false,
                    (Dialect::MicroModem1, "ALL") => {
                        let lines: Vec<NmeaSentence> = self
                            .settings
                            .iter()
                            .map(|(k, v)| config_line(k, v))
                            .collect();
                        self.out.extend(lines);
                    }
                    _ => match self.settings.get(&key).cloned() {
                        Some(v) => self.out.push(config_line(&key, &v)),
                        None => self.error("CFG", "2", format!("unknown parameter {key}")),
                    },
                }
            }
            "CLK" => self.set_clock_by_date(nmea),
            "MSC" => self.sleep_command(nmea),
            "PDT" | "PNT" => self.interrogate(nmea),
            _ => return false,
        }
        true
    }

    /// `$CCCFG,key,value` (`ALL,0`: factory settings, the modem id kept).
    fn set_config(&mut self, nmea: &NmeaSentence) {
        let key = nmea.field(0).unwrap_or("").trim().to_string();
        let value = nmea.field(1).unwrap_or("").trim().to_string();
        if key.is_empty() {
            return self.error("NMEA", "3", "$CCCFG field 0 (key): missing");
        }
        if key == "ALL" {
            let id = self.id().to_string();
            self.settings.clear();
            self.settings.extend(match self.config.dialect {
                Dialect::MicroModem1 => nvram::micromodem1(self.config.modem_id),
                Dialect::MicroModem2 => nvram::micromodem2(self.config.modem_id),
            });
            self.settings.insert("SRC".into(), id);
        } else {
            self.settings.insert(key.clone(), value.clone());
        }
        self.out.push(config_line(&key, &value));
    }

    /// `$CCCLK,year,month,day,hour,minute,second`: set to the second,
    /// answered by `$CACLK` (a Micro-Modem 2 also reports the new timing
    /// source, `$CATMG`).
    fn set_clock_by_date(&mut self, nmea: &NmeaSentence) {
        match MmSentence::from_nmea(nmea) {
            Ok(MmSentence::Clock { date_time, .. }) => {
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
        }
    }

    pub(super) fn set_clock(&mut self, time: u64) {
        self.clock_offset = i64::try_from(time).unwrap_or(i64::MAX)
            - i64::try_from(now_micros()).unwrap_or(i64::MAX);
    }

    /// The clock now counts as set by the host (a Micro-Modem 2 tells with
    /// `$CATMG` when that is new).
    pub(super) fn clock_source_changed(&mut self) {
        if self.clock_source != ClockSource::UserCommand {
            self.clock_source = ClockSource::UserCommand;
            if self.mm2.is_some() {
                let now = self.clock();
                self.out
                    .push(mm2::timing(false, now, ClockSource::UserCommand));
            }
        }
    }

    /// The clock field of `$CACST`: the bit field of clock and pulse source
    /// (Micro-Modem 2 firmware 2.0.26038 on), else Goby's clock mode (0
    /// unset, 1 set by the host; never synchronised to a pulse).
    fn receive_clock_mode(&self) -> u32 {
        if firmware::toa_mode_is_bitfield(&self.config.version) {
            self.clock_source.receive_clock_bits()
        } else {
            u32::from(self.clock_source == ClockSource::UserCommand)
        }
    }

    /// The clock mode of `$CAXST`.
    pub(super) fn transmit_clock_mode(&self) -> u32 {
        if self.mm2.is_some() {
            self.clock_source.transmit_clock_mode()
        } else {
            u32::from(self.clock_source == ClockSource::UserCommand)
        }
    }

    /// `$CCMSC,src,dest,minutes`: see the module documentation.
    fn sleep_command(&mut self, nmea: &NmeaSentence) {
        let field = |i: usize, name: &str| -> Result<i64, String> {
            let t = nmea.field(i).unwrap_or("").trim();
            t.parse()
                .map_err(|_| format!("$CCMSC field {i} ({name}): {t:?} is not an integer"))
        };
        let parsed =
            field(0, "src").and_then(|src| Ok((src, field(1, "dest")?, field(2, "minutes")?)));
        let (src, dest, minutes) = match parsed {
            Ok(v) => v,
            Err(e) => return self.error("NMEA", "3", e),
        };
        if dest != i64::from(self.id()) {
            return self.error(
                "MSC",
                "1",
                format!(
                    "$CCMSC field 1 (dest): {dest} is not this modem ({}): an acoustic sleep command is not emulated",
                    self.id()
                ),
            );
        }
        let until = match minutes {
            0 => Some(Instant::now() + self.config.boot_time),
            m if m > 0 => Some(Instant::now() + Duration::from_secs(60 * m.unsigned_abs())),
            SLEEP_UNTIL_WOKEN => None,
            m => {
                return self.error(
                    "NMEA",
                    "3",
                    format!(
                        "$CCMSC field 2 (minutes): {m} is neither -1, 0 nor a number of minutes"
                    ),
                )
            }
        };
        self.out.push(NmeaSentence::new(
            "CA",
            "MSC",
            vec![src.to_string(), dest.to_string(), minutes.to_string()],
        ));
        self.halt();
        self.asleep = Some(Asleep { until });
    }

    /// A host line while asleep: not read (recorded); a modem sleeping
    /// until woken wakes and boots.
    pub(super) fn line_while_asleep(&mut self, line: &[u8]) {
        self.ignore(String::from_utf8_lossy(line).into_owned());
        if self.asleep.is_some_and(|a| a.until.is_none()) {
            self.reset();
        }
    }

    /// Runs the timers that are due.
    pub(super) fn run_timers(&mut self, now: Instant) {
        let (due, later): (Vec<_>, Vec<_>) = std::mem::take(&mut self.timers)
            .into_iter()
            .partition(|(t, _)| *t <= now);
        self.timers = later;
        // One packet on the water at a time: a transmission waits for the
        // one under way.
        let water_clear = self.on_water.iter().map(|p| p.ends).max();
        for (_, timer) in due {
            if let (
                Some(clear),
                Timer::SendInit | Timer::SendPoll(_) | Timer::SendData | Timer::SendFdp(_),
            ) = (water_clear, &timer)
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
                    let source = self.clock_source;
                    self.out.push(mm2::timing(true, time, source));
                }
                Timer::SendInit => self.send_init(),
                Timer::SendPoll(cycle) => self.send_poll(cycle),
                Timer::SendData => {
                    let has_backend = self.has_backend;
                    self.send_cycle(has_backend);
                }
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
        self.put_cycle_init(cycle, WaterKind::CycleInit);
    }

    /// `$CCCYC` naming another modem as the sender: a poll, asking it for
    /// its data with a cycle-initialization packet (after the transmit
    /// delay). Whoever hears the packet reports the cycle (`$CACYC`); the
    /// polled modem then runs it.
    pub(super) fn poll(&mut self, cycle: Cycle) {
        if rate::spec(cycle.rate as i32).is_none() {
            return self.error("CYC", "1", format!("bad rate {}", cycle.rate));
        }
        self.schedule_after_tx_delay(Timer::SendPoll(cycle));
    }

    fn send_poll(&mut self, cycle: Cycle) {
        // This modem announced the cycle: the polled modem's rate-0 data
        // follows without a `$CACYC` of its own.
        self.announced_by = Some(cycle.src);
        self.put_cycle_init(cycle, WaterKind::Poll);
    }

    /// Puts a cycle-initialization packet for `cycle` on the water, heard
    /// by every modem (a poll must reach the polled one).
    fn put_cycle_init(&mut self, cycle: Cycle, kind: WaterKind) {
        self.say(MmSentence::TransmitStart { bytes: 0 });
        let packet = MicroModemEmulatedPacket {
            kind: Kind::CycleInit as i32,
            rate: Some(cycle.rate),
            ack_requested: Some(cycle.ack),
            frame_count: Some(cycle.frames),
            cycle_src: Some(cycle.src),
            cycle_dest: Some(cycle.dest),
            ..Default::default()
        };
        let xst = self.transmit_stats(cycle, 1, PacketType::FskMini, 0);
        let me = self.id();
        let dest = if kind == WaterKind::Poll {
            0
        } else {
            cycle.dest
        };
        self.transmit(
            wrap(me, dest, packet),
            self.config.packet_overhead,
            kind,
            0,
            Some(xst),
        );
    }

    /// `$CAXST`, when XST is on.
    pub(super) fn send_transmit_stats(&mut self, xst: &TransmitStats) {
        if self.setting_on("XST") {
            let layout = self.layout();
            self.out.push(xst.to_nmea(layout));
        }
    }

    /// `$CAXST` for a ping, ping reply or mini-packet the backend sent.
    pub(super) fn sent_special(
        &mut self,
        mt: &ModemTransmission,
        packet: &MicroModemEmulatedPacket,
    ) {
        if !matches!(packet.kind(), Kind::Ping | Kind::PingReply | Kind::Mini) {
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
        self.send_transmit_stats(&xst);
    }

    /// Whether a rate-0 data packet from `src` was announced by a
    /// cycle-initialization packet (then its `$CACYC` was already reported).
    pub(super) fn take_announced(&mut self, src: u32, rate: u32) -> bool {
        if rate == 0 && self.announced_by == Some(src) {
            self.announced_by = None;
            true
        } else {
            false
        }
    }

    /// A cycle-initialization packet heard (from `src`, the modem that sent
    /// it): `$CACYC` for its cycle (and `$CACST`); when it polls this modem,
    /// this modem's cycle starts: `$CADRQ` for the data.
    pub(super) fn receive_cycle_init(
        &mut self,
        src: u32,
        dest: u32,
        packet: &MicroModemEmulatedPacket,
    ) {
        let cycle = Cycle {
            src: packet.cycle_src.unwrap_or(src),
            dest: packet.cycle_dest.unwrap_or(dest),
            rate: packet.rate(),
            ack: packet.ack_requested(),
            frames: packet.frame_count(),
        };
        let me = self.id();
        if cycle.src != me && cycle.dest != me && cycle.dest != 0 {
            // Between two other modems: not ours to report.
            return;
        }
        self.say(MmSentence::Cycle {
            from_modem: true,
            cycle,
        });
        self.receive_stats(src, dest, packet.rate(), PacketType::FskMini, 1, 0);
        if cycle.src == me {
            self.polled(cycle);
        } else {
            self.announced_by = Some(cycle.src);
        }
    }

    /// This modem was polled: its cycle runs as if its host had started it,
    /// without a cycle-initialization packet of its own.
    fn polled(&mut self, cycle: Cycle) {
        if self.tx.is_some() {
            return self.error("CYC", "2", "polled while a cycle is under way");
        }
        let Some(spec) = rate::spec(cycle.rate as i32) else {
            return self.error("CYC", "1", format!("bad rate {}", cycle.rate));
        };
        self.tx = Some(TxCycle {
            cycle: Cycle {
                frames: cycle.frames.clamp(1, spec.frames),
                ..cycle
            },
            frames: Vec::new(),
            deadline: Instant::now(),
        });
        self.request_frame(1);
    }

    /// `$CACST` of a packet from `src`, from the simulated link, when CST
    /// is on.
    pub(super) fn receive_stats(
        &mut self,
        src: u32,
        dest: u32,
        rate: u32,
        packet_type: PacketType,
        frames: u32,
        bad_frames: u32,
    ) {
        if !self.setting_on("CST") {
            return;
        }
        let stats = link_stats(
            self,
            LinkPacket {
                src,
                dest,
                rate,
                packet_type,
                frames,
                bad_frames,
            },
        );
        let layout = self.layout();
        self.out.push(stats.to_nmea(layout));
    }

    /// `$CCPDT` / `$CCPNT`: echoed (talker `SN`), then after the timeout
    /// `$SNTTA` with the travel times to the transponders of the geometry.
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
fn link_stats(modem: &Modem, p: LinkPacket) -> ReceiveStats {
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
        clock_mode: modem.receive_clock_mode(),
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

/// `$CACFG,key,value`.
pub(super) fn config_line(key: &str, value: &str) -> NmeaSentence {
    NmeaSentence::new("CA", "CFG", vec![key.to_string(), value.to_string()])
}

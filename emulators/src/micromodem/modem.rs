//! The emulated modem's state: what it answers on the serial line, what it
//! puts on the water and what it reports of what it hears. Behaviour common
//! to both generations lives here (with the timers, the clock, the
//! statistics, the rate-0 cycle initialization, `$CCMSC` and long-baseline
//! ranging in [`super::common`]); what only a Micro-Modem 2 does is in
//! [`super::modem2`].

use std::collections::{BTreeMap, VecDeque};
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{
    micro_modem_emulated_packet::Kind, modem_transmission::TransmissionType,
    MicroModemEmulatedPacket, ModemTransmission,
};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use tokio::time::Instant;

use super::common::{Asleep, Timer};
use super::mm2::ClockSource;
use super::modem2::Mm2State;
use super::stats::{PacketType, TransmitStats};
use super::{nvram, AirKind, AirLog, AirTime, Dialect, EmulatorConfig, LineLog};
use modemdriver::driver::{DriverEvent, TransmitOutcome};
use modemdriver::micromodem::nmea::NmeaSentence;
use modemdriver::micromodem::sentence::{Cycle, MmSentence, SentenceError};
use modemdriver::rate;
use modemdriver::time::{hhmmss, now_micros};

/// A two-way ping waiting for its reply.
#[derive(Debug, Clone, Copy)]
pub(super) struct PendingPing {
    pub(super) dest: u32,
    /// When the ping left (end of its time on the backend).
    pub(super) sent: Option<Instant>,
    /// With no backend: when the reply for `lone_range` is due.
    pub(super) reply_at: Option<Instant>,
    pub(super) deadline: Instant,
}

/// A transmission being assembled from `$CCTXD`s.
pub(super) struct TxCycle {
    pub(super) cycle: Cycle,
    pub(super) frames: Vec<Vec<u8>>,
    pub(super) deadline: Instant,
}

/// What a packet on the water is.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum WaterKind {
    /// Data of this modem's cycle.
    Data,
    /// The cycle-initialization packet of a rate-0 cycle.
    CycleInit,
    /// A cycle-initialization packet polling another modem.
    Poll,
    /// An acknowledgement.
    Ack,
    /// A Flexible Data Protocol packet (Micro-Modem 2).
    FlexibleData,
}

/// A packet on the water, handed to the backend when it ends.
pub(super) struct OnWater {
    pub(super) start: u64,
    pub(super) ends: Instant,
    pub(super) packet: ModemTransmission,
    pub(super) kind: WaterKind,
    /// Bytes reported by `$CATXP` / `$CATXF`.
    pub(super) bytes: u32,
    /// Micro-Modem 2: the transmit statistics sent when it ends.
    pub(super) xst: Option<TransmitStats>,
}

pub(super) struct Modem {
    pub(super) config: EmulatorConfig,
    pub(super) on_water: Vec<OnWater>,
    air: AirLog,
    pub(super) ignored: LineLog,
    rng: ChaCha8Rng,
    pub(super) bad_crc_next: u32,
    pub(super) lose_acks_next: u32,
    pub(super) reset_mid_packet: u32,
    reset_at: Option<Instant>,
    pub(super) settings: BTreeMap<String, String>,
    pub(super) tx: Option<TxCycle>,
    /// Frames handed to the backend, waiting for its data request.
    backend_frames: Vec<Vec<u8>>,
    /// Pending two-way ping.
    pub(super) ping: Option<PendingPing>,
    /// Micro-Modem 2 only.
    pub(super) mm2: Option<Mm2State>,
    /// Modem clock minus host clock, µs.
    pub(super) clock_offset: i64,
    pub(super) clock_source: ClockSource,
    /// What the modem does later.
    pub(super) timers: Vec<(Instant, Timer)>,
    /// Sender of the last rate-0 cycle-initialization packet heard.
    pub(super) announced_by: Option<u32>,
    /// Asleep or rebooting (`$CCMSC`): deaf and mute.
    pub(super) asleep: Option<Asleep>,
    /// Packets go to a backend (else nowhere).
    pub(super) has_backend: bool,
    pub(super) out: Vec<NmeaSentence>,
    pub(super) backend_out: Vec<ModemTransmission>,
}

impl Modem {
    pub(super) fn new(config: EmulatorConfig, air: AirLog, ignored: LineLog) -> Modem {
        let mut settings = BTreeMap::new();
        let mm2 = match config.dialect {
            Dialect::MicroModem1 => {
                settings.extend(nvram::micromodem1(config.modem_id));
                None
            }
            Dialect::MicroModem2 => {
                settings.extend(super::nvram::micromodem2(config.modem_id));
                Some(Mm2State::new())
            }
        };
        let rng = ChaCha8Rng::seed_from_u64(
            config.faults.seed ^ u64::from(config.modem_id).wrapping_mul(0x9e37_79b9_7f4a_7c15),
        );
        Modem {
            config,
            on_water: Vec::new(),
            air,
            ignored,
            rng,
            bad_crc_next: 0,
            lose_acks_next: 0,
            reset_mid_packet: 0,
            reset_at: None,
            settings,
            tx: None,
            backend_frames: Vec::new(),
            ping: None,
            mm2,
            clock_offset: 0,
            clock_source: ClockSource::Rtc,
            timers: Vec::new(),
            announced_by: None,
            asleep: None,
            has_backend: false,
            out: Vec::new(),
            backend_out: Vec::new(),
        }
    }

    pub(super) fn id(&self) -> u32 {
        self.settings
            .get("SRC")
            .and_then(|s| s.parse().ok())
            .unwrap_or(self.config.modem_id)
    }

    /// The modem's clock, microseconds since the epoch (the host's clock
    /// unless the host set it otherwise).
    pub(super) fn clock(&self) -> u64 {
        now_micros().saturating_add_signed(self.clock_offset)
    }

    pub(super) fn now_time(&self) -> String {
        hhmmss(self.clock())
    }

    pub(super) fn say(&mut self, sentence: MmSentence) {
        self.out.push(sentence.to_nmea());
    }

    pub(super) fn revision(&mut self, ident: &str) {
        self.say(MmSentence::Revision {
            time: self.now_time(),
            ident: ident.into(),
            version: self.config.version.clone(),
        });
        if self.mm2.is_some() {
            // A Micro-Modem 2 names its coprocessor's firmware too.
            self.say(MmSentence::Revision {
                time: self.now_time(),
                ident: "COPROC".into(),
                version: self.config.coproc_version.clone(),
            });
        }
    }

    pub(super) fn error(&mut self, module: &str, code: &str, message: impl Into<String>) {
        self.say(MmSentence::Error {
            time: self.now_time(),
            module: module.into(),
            code: code.into(),
            message: message.into(),
        });
    }

    /// The modem restarts: what was under way is forgotten (the NVRAM
    /// stays); the clock runs on but counts as unset. `$CAREV,…,INIT`.
    pub(super) fn reset(&mut self) {
        self.halt();
        self.revision("INIT");
    }

    /// Everything under way stops (a reset, sleep, power loss).
    pub(super) fn halt(&mut self) {
        self.tx = None;
        self.ping = None;
        self.backend_frames.clear();
        self.timers.clear();
        self.announced_by = None;
        self.asleep = None;
        self.clock_source = ClockSource::Rtc;
        if let Some(mm2) = &mut self.mm2 {
            mm2.restart();
        }
        // What is on the water stops: nobody receives it.
        let now = now_micros();
        for p in std::mem::take(&mut self.on_water) {
            self.log_air(AirTime {
                start: p.start,
                end: now,
                kind: if p.kind == WaterKind::Ack {
                    AirKind::Ack
                } else {
                    AirKind::Aborted
                },
            });
        }
    }

    /// The modem loses power: everything under way stops.
    pub(super) fn power_off(&mut self) {
        self.reset();
        self.out.clear();
    }

    fn log_air(&self, time: AirTime) {
        if let Ok(mut log) = self.air.lock() {
            log.push(time);
        }
    }

    /// Puts a packet on the water for `duration`.
    pub(super) fn transmit(
        &mut self,
        packet: ModemTransmission,
        duration: Duration,
        kind: WaterKind,
        bytes: u32,
        xst: Option<TransmitStats>,
    ) {
        if matches!(kind, WaterKind::Data | WaterKind::FlexibleData) && self.reset_mid_packet > 0 {
            self.reset_mid_packet -= 1;
            self.reset_at = Some(Instant::now() + duration / 2);
        }
        self.on_water.push(OnWater {
            start: now_micros(),
            ends: Instant::now() + duration,
            packet,
            kind,
            bytes,
            xst,
        });
    }

    /// Draws a fault: a scripted one first, then by probability.
    pub(super) fn draw(&mut self, scripted: fn(&mut Modem) -> &mut u32, probability: f64) -> bool {
        let n = scripted(self);
        if *n > 0 {
            *n -= 1;
            return true;
        }
        probability > 0.0 && self.rng.random_bool(probability.min(1.0))
    }

    pub(super) fn request_frame(&mut self, frame: u32) {
        let time = self.now_time();
        let Some(tx) = &mut self.tx else { return };
        let max_bytes = rate::spec(tx.cycle.rate as i32).map_or(32, |s| s.frame_bytes);
        tx.deadline = Instant::now() + self.config.data_timeout;
        let c = tx.cycle;
        self.say(MmSentence::DataRequest {
            time,
            src: c.src,
            dest: c.dest,
            ack: c.ack,
            max_bytes,
            frame,
        });
    }

    pub(super) fn line(&mut self, line: &[u8], has_backend: bool) {
        self.has_backend = has_backend;
        if self.asleep.is_some() {
            self.line_while_asleep(line);
            return;
        }
        let nmea = match NmeaSentence::parse(line) {
            Ok(s) => s,
            Err(e) => return self.error("NMEA", "2", format!("bad sentence: {e}")),
        };
        if self.mm2.is_some() && nmea.talker != "CA" && self.mm2_busy(&nmea) {
            return;
        }
        if self.common_line(&nmea) {
            return;
        }
        if self.mm2.is_some() && self.mm2_line(&nmea) {
            return;
        }
        let sentence = match MmSentence::from_nmea(&nmea) {
            Ok(s) => s,
            Err(SentenceError::Unknown(address)) if address.starts_with("CA") => return,
            Err(e) => return self.error("NMEA", "3", e.to_string()),
        };
        match sentence {
            MmSentence::Cycle {
                from_modem: false,
                cycle,
            } => {
                self.say(MmSentence::Cycle {
                    from_modem: true,
                    cycle,
                });
                if cycle.src != self.id() {
                    // A poll of another modem: its cycle-initialization
                    // packet asks it for its data.
                    return self.poll(cycle);
                }
                let Some(spec) = rate::spec(cycle.rate as i32) else {
                    return self.error("CYC", "1", format!("bad rate {}", cycle.rate));
                };
                let frames = cycle.frames.clamp(1, spec.frames);
                self.tx = Some(TxCycle {
                    cycle: Cycle { frames, ..cycle },
                    frames: Vec::new(),
                    deadline: Instant::now(),
                });
                if cycle.rate == 0 {
                    // The cycle-initialization packet goes first; the data
                    // is asked for once it is on its way.
                    self.hold_cycle();
                    self.schedule_after_tx_delay(Timer::SendInit);
                } else {
                    self.request_frame(1);
                }
            }
            MmSentence::TransmitData {
                src,
                dest,
                ack,
                data,
            } => {
                let Some(tx) = &mut self.tx else {
                    return self.error("TXD", "5", "no cycle in progress");
                };
                let bytes = data.len() as u32;
                tx.frames.push(data);
                let next = tx.frames.len() as u32 + 1;
                let done = next > tx.cycle.frames;
                self.say(MmSentence::TransmitDataEcho {
                    src,
                    dest,
                    ack,
                    bytes,
                });
                if !done {
                    self.request_frame(next);
                } else {
                    self.hold_cycle();
                    self.schedule_after_tx_delay(Timer::SendData);
                }
            }
            MmSentence::Ping {
                from_modem: false,
                src,
                dest,
            } => {
                self.say(MmSentence::Ping {
                    from_modem: true,
                    src,
                    dest,
                });
                let deadline = Instant::now() + self.config.ping_timeout;
                let reply_at = match (has_backend, self.config.lone_range) {
                    (false, Some(range)) => Some(
                        Instant::now() + Duration::from_secs_f64(2.0 * range.max(0.0) / 1500.0),
                    ),
                    _ => None,
                };
                if has_backend {
                    self.backend_out
                        .push(special(self.id(), dest, Kind::Ping, 0));
                }
                self.ping = Some(PendingPing {
                    dest,
                    sent: None,
                    reply_at,
                    deadline,
                });
            }
            MmSentence::MiniPacket {
                from_modem: false,
                src,
                dest,
                value,
            } => {
                self.say(MmSentence::MiniPacket {
                    from_modem: true,
                    src,
                    dest,
                    value,
                });
                self.backend_out
                    .push(special(self.id(), dest, Kind::Mini, u32::from(value)));
            }
            other => {
                let nmea = other.to_nmea();
                // Never answer the modem's own sentences: a line that echoes
                // would otherwise loop forever.
                if nmea.talker != "CA" {
                    self.error("NMEA", "4", format!("unexpected ${}", nmea.address()));
                }
            }
        }
    }

    /// Puts the assembled cycle on the water (Micro-Modem 1: at once, and
    /// with no backend it is done at once too).
    pub(super) fn send_cycle(&mut self, has_backend: bool) {
        let Some(tx) = self.tx.take() else { return };
        let bytes: u32 = tx.frames.iter().map(|f| f.len() as u32).sum();
        self.say(MmSentence::TransmitStart { bytes });
        if !has_backend && self.mm2.is_none() {
            self.say(MmSentence::TransmitDone { bytes });
            return;
        }
        let spec = rate::spec(tx.cycle.rate as i32).unwrap_or(rate::spec(0).expect("rate 0"));
        let frames_sent = tx.frames.len() as u32;
        let packet = MicroModemEmulatedPacket {
            kind: Kind::Data as i32,
            rate: Some(tx.cycle.rate),
            ack_requested: Some(tx.cycle.ack),
            frame: tx.frames,
            ..Default::default()
        };
        let mt = ModemTransmission {
            src: Some(tx.cycle.src as i32),
            dest: Some(tx.cycle.dest as i32),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            frame: vec![packet.encode_to_vec()],
            ..Default::default()
        };
        let xst = self.transmit_stats(
            tx.cycle,
            frames_sent,
            if tx.cycle.rate == 0 {
                PacketType::Fsk
            } else {
                PacketType::Psk
            },
            bytes,
        );
        self.transmit(
            mt,
            spec.packet_duration(self.config.packet_overhead),
            WaterKind::Data,
            bytes,
            Some(xst),
        );
    }

    pub(super) fn timers(&mut self, now: Instant) {
        if self.reset_at.is_some_and(|t| t <= now) {
            self.reset_at = None;
            self.reset();
        }
        if self
            .asleep
            .is_some_and(|a| a.until.is_some_and(|t| t <= now))
        {
            // Awake again: the modem boots.
            self.reset();
        }
        let (done, going): (Vec<OnWater>, Vec<OnWater>) = std::mem::take(&mut self.on_water)
            .into_iter()
            .partition(|p| p.ends <= now);
        self.on_water = going;
        for p in done {
            self.log_air(AirTime {
                start: p.start,
                end: now_micros(),
                kind: match p.kind {
                    WaterKind::Data => AirKind::Data,
                    WaterKind::Ack => AirKind::Ack,
                    WaterKind::CycleInit | WaterKind::Poll => AirKind::CycleInit,
                    WaterKind::FlexibleData => AirKind::FlexibleData,
                },
            });
            self.backend_out.push(p.packet);
            self.say(MmSentence::TransmitDone { bytes: p.bytes });
            if let Some(xst) = p.xst {
                self.send_transmit_stats(&xst);
            }
            if p.kind == WaterKind::CycleInit {
                self.request_frame(1);
            }
        }
        if self.tx.as_ref().is_some_and(|tx| tx.deadline <= now) {
            self.tx = None;
            self.error("CYC", "4", "DATA_TIMEOUT");
        }
        if let Some(ping) = self.ping {
            if ping.reply_at.is_some_and(|at| at <= now) {
                let range = self.config.lone_range.unwrap_or(0.0).max(0.0);
                self.ping = None;
                self.say(MmSentence::PingReply {
                    src: ping.dest,
                    dest: self.id(),
                    travel_time: range / 1500.0,
                });
            } else if ping.deadline <= now {
                self.ping = None;
                self.say(MmSentence::Message {
                    kind: "PING_TIMEOUT".into(),
                    value: ping.dest.to_string(),
                });
            }
        }
        self.mm2_timers(now);
        self.run_timers(now);
    }

    pub(super) fn next_deadline(&self) -> Option<Instant> {
        let ping = self
            .ping
            .map(|p| p.reply_at.map_or(p.deadline, |at| at.min(p.deadline)));
        let water = self.on_water.iter().map(|p| p.ends).min();
        [
            self.tx.as_ref().map(|t| t.deadline),
            ping,
            water,
            self.reset_at,
            self.mm2.as_ref().and_then(Mm2State::next_deadline),
            self.timers.iter().map(|(t, _)| *t).min(),
            self.asleep.and_then(|a| a.until),
        ]
        .into_iter()
        .flatten()
        .min()
    }

    pub(super) fn backend_event(&mut self, event: DriverEvent) {
        let me = self.id() as i32;
        match event {
            DriverEvent::DataRequest(request) => {
                let mut filled = request.template().clone();
                if filled.r#type() == TransmissionType::Data {
                    filled.frame = std::mem::take(&mut self.backend_frames);
                }
                request.respond(filled);
            }
            DriverEvent::TransmitResult(result) => {
                let mt = &result.transmission;
                if mt.r#type() == TransmissionType::Data {
                    match result.outcome {
                        TransmitOutcome::Sent | TransmitOutcome::NothingToSend => {
                            let bytes = mt.frame.iter().map(|f| f.len() as u32).sum();
                            self.say(MmSentence::TransmitDone { bytes });
                        }
                        TransmitOutcome::Failed(reason) => self.error("TXD", "6", reason),
                    }
                } else {
                    let packet = decode_special(mt);
                    if let Some(ping) = &mut self.ping {
                        if ping.sent.is_none()
                            && packet.as_ref().is_some_and(|p| p.kind() == Kind::Ping)
                        {
                            ping.sent = Some(Instant::now());
                        }
                    }
                    if let Some(packet) = packet {
                        self.sent_special(mt, &packet);
                    }
                }
            }
            // Asleep or booting, the modem hears nothing.
            DriverEvent::Received(_) if self.asleep.is_some() => {}
            DriverEvent::Received(mt) => {
                let src = mt.src().max(0) as u32;
                let dest = mt.dest().max(0) as u32;
                match mt.r#type() {
                    TransmissionType::Data if mt.dest() == me || mt.dest() == 0 => {
                        self.say(MmSentence::Cycle {
                            from_modem: true,
                            cycle: Cycle {
                                src,
                                dest,
                                rate: mt.rate().max(0) as u32,
                                ack: mt.ack_requested(),
                                frames: mt.frame.len() as u32,
                            },
                        });
                        for (i, data) in mt.frame.iter().enumerate() {
                            self.say(MmSentence::ReceiveData {
                                src,
                                dest,
                                ack: mt.ack_requested(),
                                frame: mt.frame_start() + i as u32 + 1,
                                data: data.clone(),
                            });
                        }
                    }
                    TransmissionType::Ack if mt.dest() == me => {
                        for f in &mt.acked_frame {
                            self.say(MmSentence::Ack {
                                src,
                                dest,
                                frame: (*f).max(0) as u32 + 1,
                            });
                        }
                    }
                    TransmissionType::DriverSpecific if mt.dest() == me || mt.dest() == 0 => {
                        let Some(packet) = decode_special(&mt) else {
                            return;
                        };
                        self.receive_special(src, dest, &packet);
                    }
                    _ => {}
                }
            }
            _ => {}
        }
    }

    /// A packet between emulators heard (addressed to us or broadcast).
    fn receive_special(&mut self, src: u32, dest: u32, packet: &MicroModemEmulatedPacket) {
        let me = self.id();
        match packet.kind() {
            Kind::Data => self.receive_data(src, dest, packet),
            Kind::Ack if dest == me => {
                for frame in &packet.acked_frame {
                    self.say(MmSentence::Ack {
                        src,
                        dest,
                        frame: *frame,
                    });
                }
                let mini = mini_type(packet.rate());
                self.receive_stats(src, dest, packet.rate(), mini, 1, 0);
            }
            Kind::Ack => {}
            Kind::Ping => {
                self.say(MmSentence::PingHeard { src, dest });
                self.receive_stats(src, dest, 0, PacketType::FskMini, 1, 0);
                self.backend_out
                    .push(special(self.id(), src, Kind::PingReply, 0));
            }
            Kind::PingReply => {
                if let Some(PendingPing {
                    dest: pinged,
                    sent: Some(sent),
                    ..
                }) = self.ping
                {
                    if pinged == src {
                        self.ping = None;
                        let rtt = sent.elapsed().saturating_sub(self.config.ping_packet);
                        self.say(MmSentence::PingReply {
                            src,
                            dest: self.id(),
                            travel_time: rtt.as_secs_f64() / 2.0,
                        });
                        self.receive_stats(src, dest, 0, PacketType::FskMini, 1, 0);
                    }
                }
            }
            Kind::Mini => {
                self.say(MmSentence::MiniPacketReceived {
                    src,
                    dest,
                    value: (packet.mini_data() & 0x1fff) as u16,
                });
                self.receive_stats(src, dest, 0, PacketType::FskMini, 1, 0);
            }
            Kind::CycleInit => self.receive_cycle_init(src, dest, packet),
            Kind::Fdp => self.receive_fdp(src, dest, packet),
        }
    }

    /// A data packet heard: `$CACYC`, then per frame `$CARXD` or, for a
    /// frame failing its CRC, `$CAMSG,BAD_CRC`; frames addressed to this
    /// modem that passed are acknowledged (unless the ack is lost). The
    /// packet's statistics follow its frames; after a rate-0
    /// cycle-initialization packet from the same sender the `$CACYC` is not
    /// repeated.
    fn receive_data(&mut self, src: u32, dest: u32, packet: &MicroModemEmulatedPacket) {
        let ack = packet.ack_requested();
        let announced = self.take_announced(src, packet.rate());
        if !announced {
            self.say(MmSentence::Cycle {
                from_modem: true,
                cycle: Cycle {
                    src,
                    dest,
                    rate: packet.rate(),
                    ack,
                    frames: packet.frame.len() as u32,
                },
            });
        }
        let mut good = Vec::new();
        for (i, data) in packet.frame.iter().enumerate() {
            let frame = i as u32 + 1;
            let bad_crc = self.config.faults.bad_crc;
            if self.draw(|m| &mut m.bad_crc_next, bad_crc) {
                self.say(MmSentence::Message {
                    kind: "BAD_CRC".into(),
                    value: frame.to_string(),
                });
                continue;
            }
            good.push(frame);
            self.say(MmSentence::ReceiveData {
                src,
                dest,
                ack,
                frame,
                data: data.clone(),
            });
        }
        let frames = packet.frame.len() as u32;
        let kind = if packet.rate() == 0 {
            PacketType::Fsk
        } else {
            PacketType::Psk
        };
        self.receive_stats(
            src,
            dest,
            packet.rate(),
            kind,
            frames,
            frames - good.len() as u32,
        );
        if !ack || dest != self.id() || good.is_empty() {
            return;
        }
        let lost_ack = self.config.faults.lost_ack;
        let lost = self.draw(|m| &mut m.lose_acks_next, lost_ack);
        let reply = MicroModemEmulatedPacket {
            kind: Kind::Ack as i32,
            acked_frame: good,
            rate: packet.rate,
            ..Default::default()
        };
        let mut mt = ModemTransmission {
            src: Some(dest as i32),
            dest: Some(src as i32),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            frame: vec![reply.encode_to_vec()],
            ..Default::default()
        };
        if lost {
            // On the water all the same, but nobody hears it.
            mt.dest = Some(i32::MAX);
        }
        self.say(MmSentence::TransmitStart { bytes: 0 });
        let cycle = Cycle {
            src: dest,
            dest: src,
            rate: packet.rate(),
            ack: false,
            frames: 0,
        };
        let xst = self.transmit_stats(cycle, 0, mini_type(packet.rate()), 0);
        self.transmit(
            mt,
            self.config.packet_overhead,
            WaterKind::Ack,
            0,
            Some(xst),
        );
    }

    /// Transmit statistics of a packet of `cycle` starting now.
    pub(super) fn transmit_stats(
        &self,
        cycle: Cycle,
        frames_sent: u32,
        packet_type: PacketType,
        bytes: u32,
    ) -> TransmitStats {
        TransmitStats {
            time: self.clock(),
            clock_mode: self.transmit_clock_mode(),
            mode: 0,
            probe_length: match packet_type {
                PacketType::Fsk | PacketType::FskMini => 40,
                _ => 200,
            },
            bandwidth: super::geometry::BANDWIDTH_HZ,
            carrier: super::geometry::CARRIER_HZ,
            rate: cycle.rate as i32,
            src: cycle.src,
            dest: cycle.dest,
            ack: cycle.ack,
            frames_expected: cycle.frames,
            frames_sent,
            packet_type,
            bytes,
        }
    }

    /// Records a host line the modem did not act on.
    pub(super) fn ignore(&mut self, line: String) {
        if let Ok(mut log) = self.ignored.lock() {
            log.push(line);
        }
    }
}

/// Packet type of an acknowledgement at `rate`.
pub(super) fn mini_type(rate: u32) -> PacketType {
    if rate == 0 {
        PacketType::FskMini
    } else {
        PacketType::PskMini
    }
}

pub(super) fn special(src: u32, dest: u32, kind: Kind, mini: u32) -> ModemTransmission {
    let packet = MicroModemEmulatedPacket {
        kind: kind as i32,
        mini_data: (kind == Kind::Mini).then_some(mini),
        ..Default::default()
    };
    wrap(src, dest, packet)
}

/// A packet between emulators as the backend carries it.
pub(super) fn wrap(src: u32, dest: u32, packet: MicroModemEmulatedPacket) -> ModemTransmission {
    ModemTransmission {
        src: Some(src as i32),
        dest: Some(dest as i32),
        r#type: Some(TransmissionType::DriverSpecific as i32),
        frame: vec![packet.encode_to_vec()],
        ..Default::default()
    }
}

pub(super) fn decode_special(mt: &ModemTransmission) -> Option<MicroModemEmulatedPacket> {
    mt.frame
        .first()
        .and_then(|f| MicroModemEmulatedPacket::decode(f.as_slice()).ok())
}

/// Lines of a configuration echo, in order.
pub(super) type Echo = VecDeque<NmeaSentence>;

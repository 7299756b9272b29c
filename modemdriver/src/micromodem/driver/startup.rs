//! Start-up and configuration; host commands and the modem's answers.
//!
//! At start, after a modem reset (`$CAREV` with ident `INIT`) and after a
//! reconnection the driver queues: `$CCCFG,ALL,0` (with `reset_nvram`),
//! `$CCCFG,SRC,<modem_id>`, every `nvram_cfg` `KEY,VALUE`, `CST,1` and
//! `XST,1` unless configured, `$CCCFQ,ALL` (`TOP` on a Micro-Modem 2; with
//! `query_cfg_on_startup`), then the clock (`$CCTMS` on a Micro-Modem 2,
//! `$CCCLK` otherwise, written 50-100 ms into a second of the wall clock:
//! [`clock::wait_for_send`]). One command is out at a time, awaiting its
//! answer (matched by sentence name, [`answers`]) for `response_timeout_ms`
//! and sent again up to `max_retries` times; the configuration query's
//! answer is many `$CACFG` lines, over when `config_echo_quiet_ms` pass
//! without one. The clock's answer is checked against the time asked for
//! (`allowed_skew_ms`). When the queue is empty the driver is `Ready`.
//!
//! The generation (Micro-Modem 1 or 2) is told by `$CAREV`'s firmware
//! version or by the configuration echo's parameter names
//! ([`Generation`]); whether the modem sends statistics by the echo of `CST`
//! and `XST` and by the statistics heard.

use super::super::clock;
use super::super::firmware::Generation;
use super::super::sentence::MmSentence;
use super::machine::Machine;
use super::settings::STATISTICS_SETTINGS;
use super::state::{Awaiting, Command};
use crate::driver::DriverStatus;

/// The sentence id of the modem's answer to a host command.
fn answer_id(command: &MmSentence) -> Option<&'static str> {
    use MmSentence as S;
    Some(match command {
        S::SetConfig { .. } | S::QueryConfig { .. } => "CFG",
        S::Clock {
            from_modem: false, ..
        } => "CLK",
        S::TimeSet { .. } => "TMS",
        S::TimeQuery { .. } => "TMQ",
        S::Cycle {
            from_modem: false, ..
        } => "CYC",
        S::TransmitData { .. } => "TXD",
        S::Ping {
            from_modem: false, ..
        } => "MPC",
        S::MiniPacket {
            from_modem: false, ..
        } => "MUC",
        S::FdpTransmit { .. } => "TDP",
        S::RemusLblPing { .. } => "PDT",
        S::NarrowbandLblPing { .. } => "PNT",
        S::HardwareControl { .. } => "MEC",
        _ => return None,
    })
}

/// Whether the modem's line `reply` (talker and id; parsed when it could
/// be) answers `command`. Answers are matched by sentence name, so that the
/// field differences between firmware versions do not matter; only a
/// configuration echo must name the parameter set, and a `$CACYC` naming
/// another sender is a packet heard, not our echo.
pub(super) fn answers(
    command: &MmSentence,
    talker: &str,
    id: &str,
    reply: Option<&MmSentence>,
) -> bool {
    if talker != "CA" || answer_id(command) != Some(id) {
        return false;
    }
    match (command, reply) {
        (MmSentence::SetConfig { key, .. }, Some(MmSentence::Config { key: k, .. })) => {
            k.eq_ignore_ascii_case(key)
        }
        (
            MmSentence::Cycle { cycle: a, .. },
            Some(MmSentence::Cycle {
                from_modem: true,
                cycle: b,
            }),
        ) => a.src == b.src,
        _ => true,
    }
}

impl Machine {
    /// Queues the start-up commands (dropping any queued).
    pub(super) fn queue_initialization(&mut self) {
        let s = &mut self.startup;
        s.queue.clear();
        s.clock_at = None;
        let mut set = |key: &str, value: &str| {
            s.queue.push_back(Command::Send(MmSentence::SetConfig {
                key: key.into(),
                value: value.into(),
            }))
        };
        if self.mm.reset_nvram() {
            set("ALL", "0");
        }
        set("SRC", &self.modem_id.to_string());
        let mut configured = Vec::new();
        for cfg in &self.mm.nvram_cfg {
            if let Some((key, value)) = cfg.split_once(',') {
                configured.push(key.trim().to_ascii_uppercase());
                s.queue.push_back(Command::Send(MmSentence::SetConfig {
                    key: key.trim().to_string(),
                    value: value.trim().to_string(),
                }));
            }
        }
        // Receive and transmit statistics after every packet, unless the
        // configuration says otherwise.
        for key in STATISTICS_SETTINGS {
            if !configured.iter().any(|k| k == key) {
                s.queue.push_back(Command::Send(MmSentence::SetConfig {
                    key: key.to_string(),
                    value: "1".into(),
                }));
            }
        }
        if self.mm.query_cfg_on_startup() {
            s.queue.push_back(Command::QueryConfig);
        }
        s.queue.push_back(Command::SetClock);
        s.clock_attempts = 0;
        s.initializing = true;
    }

    pub(super) fn send_awaiting(&mut self, sentence: MmSentence, attempt: u32, for_job: bool) {
        self.send_command(sentence, attempt, for_job, false, None);
    }

    /// Writes a command and awaits its answer (`response_timeout_ms`).
    fn send_command(
        &mut self,
        sentence: MmSentence,
        attempt: u32,
        for_job: bool,
        multi: bool,
        clock_asked: Option<u64>,
    ) {
        // Sent again after reconnection (initialization is queued again then).
        if self.write(sentence.clone()) {
            self.startup.awaiting = Some(Awaiting {
                sentence,
                attempt,
                deadline: self.now.at + self.response_timeout(),
                for_job,
                multi,
                heard: false,
                clock_asked,
            });
        }
    }

    /// Sends the next queued host command: `Some(true)` when one went out,
    /// `Some(false)` when the next must wait (the clock's send window),
    /// `None` when none is queued (then the start-up is over: `Ready`).
    pub(super) fn pump_commands(&mut self) -> Option<bool> {
        let Some(command) = self.startup.queue.pop_front() else {
            if self.startup.initializing {
                self.startup.initializing = false;
                self.status(DriverStatus::Ready);
            }
            return None;
        };
        match command {
            Command::Send(sentence) => self.send_awaiting(sentence, 1, false),
            Command::QueryConfig => {
                let key = match self.startup.generation {
                    Generation::Two => "TOP",
                    _ => "ALL",
                };
                let q = MmSentence::QueryConfig { key: key.into() };
                self.send_command(q, 1, false, true, None);
            }
            Command::SetClock => {
                // Sent just after the top of a second, as the modem takes
                // whole seconds (Goby does likewise): waited for once.
                match self.startup.clock_at {
                    None => {
                        let wait = clock::wait_for_send(self.now.micros);
                        if !wait.is_zero() {
                            self.startup.clock_at = Some(self.now.at + wait);
                            self.startup.queue.push_front(Command::SetClock);
                            return Some(false);
                        }
                    }
                    Some(at) if at > self.now.at => {
                        self.startup.queue.push_front(Command::SetClock);
                        return Some(false);
                    }
                    Some(_) => {}
                }
                self.startup.clock_at = None;
                self.startup.clock_attempts += 1;
                let (sentence, asked) = clock::set_clock(self.startup.generation, self.now.micros);
                self.send_command(sentence, 1, false, false, Some(asked));
            }
        }
        Some(true)
    }

    /// A line the modem sent: when it answers the command out, that
    /// command is done (a multi-line answer goes on until quiet; a clock
    /// answer is checked).
    pub(super) fn answer_heard(&mut self, sentence: &MmSentence) {
        let nmea = sentence.to_nmea();
        let answered = self
            .startup
            .awaiting
            .as_ref()
            .is_some_and(|a| answers(&a.sentence, &nmea.talker, &nmea.id, Some(sentence)));
        if !answered {
            return;
        }
        let a = self.startup.awaiting.take().expect("checked");
        if a.multi {
            // Many lines answer: done when they stop.
            self.startup.awaiting = Some(Awaiting {
                heard: true,
                deadline: self.now.at + self.config_quiet(),
                ..a
            });
        } else if let Some(asked) = a.clock_asked {
            let skew = i64::from(self.mm.allowed_skew_ms());
            if let Err(why) = clock::check_reply(sentence, asked, self.now.micros, skew) {
                self.status(DriverStatus::ModemError {
                    message: format!("clock not set: {why}"),
                });
                if self.startup.clock_attempts <= self.mm.max_retries() {
                    self.startup.queue.push_front(Command::SetClock);
                }
            }
        } else if a.for_job {
            self.job_answered();
        }
    }

    /// A line that is NMEA but not a sentence the driver can read: when it
    /// bears the name of the answer awaited, the command was heard (and is
    /// not sent again); nothing else follows from it.
    pub(super) fn unreadable_answer(&mut self, bytes: &[u8]) {
        let Ok(nmea) = super::super::nmea::NmeaSentence::parse(bytes) else {
            return;
        };
        let matched = self
            .startup
            .awaiting
            .as_ref()
            .is_some_and(|a| answers(&a.sentence, &nmea.talker, &nmea.id, None));
        if matched {
            let a = self.startup.awaiting.take().expect("checked");
            if a.multi {
                self.startup.awaiting = Some(Awaiting {
                    heard: true,
                    deadline: self.now.at + self.config_quiet(),
                    ..a
                });
            } else if a.for_job {
                self.job_answered();
            }
        }
    }

    /// The command out got no answer in time: sent again, or given up.
    pub(super) fn command_timers(&mut self) {
        let now = self.now.at;
        let Some(a) = self.startup.awaiting.take_if(|a| a.deadline <= now) else {
            return;
        };
        if a.heard {
            // A multi-line answer ended.
            return;
        }
        let command = a.sentence.to_line();
        self.status(DriverStatus::ResponseTimeout {
            command: command.clone(),
            attempt: a.attempt,
        });
        // The `$CCTDP` carries its packet's data: the modem may have taken
        // it and sent the packet with its echo lost, so it is not written
        // again (the job fails; its messages go again, marked as possible
        // repeats).
        let carries_data = matches!(a.sentence, MmSentence::FdpTransmit { .. });
        if a.attempt <= self.mm.max_retries() && !carries_data {
            self.send_command(a.sentence, a.attempt + 1, a.for_job, a.multi, a.clock_asked);
        } else if a.for_job {
            self.fail_active(format!("no answer to {command}"));
        }
    }

    /// `$CACFG,KEY,VALUE`: the configuration echo.
    pub(super) fn config_echo(&mut self, key: &str, value: &str) {
        if let Some(g) = Generation::of_config_key(key) {
            self.set_generation(g);
        }
        let on = value.trim() == "1";
        if key.eq_ignore_ascii_case("CST") {
            self.startup.cst_configured = on;
        }
        if key.eq_ignore_ascii_case("XST") {
            self.startup.xst_configured = on;
        }
        if key.eq_ignore_ascii_case("DTO") {
            if let Ok(s) = value.trim().parse::<u64>() {
                self.startup.data_timeout_s = Some(s);
            }
        }
        if key.eq_ignore_ascii_case("TXD") {
            if let Ok(ms) = value.trim().parse::<u64>() {
                self.startup.tx_delay_ms = ms;
            }
        }
    }

    /// `$CAREV`: the modem's firmware (and, with `INIT`, its start).
    pub(super) fn revision(&mut self, ident: &str, version: String) {
        // The modem's own firmware (AUV, or INIT at a start); a Micro-Modem
        // 2 also reports its coprocessor's (COPROC), whose version says
        // nothing of the generation.
        let main = ["AUV", "INIT"]
            .iter()
            .any(|i| ident.eq_ignore_ascii_case(i));
        if main {
            if let Some(g) = Generation::of_version(&version) {
                self.set_generation(g);
            }
            self.startup.firmware = Some(version);
        }
        if ident.eq_ignore_ascii_case("INIT") {
            self.modem_started();
        }
    }

    /// Receptions wait for their `$CACST` when the modem has sent one, or is
    /// a Micro-Modem 2 configured to (a Micro-Modem 1 may take the setting
    /// and send none).
    pub(super) fn expects_cst(&self) -> bool {
        let s = &self.startup;
        s.sends_cst || (s.generation == Generation::Two && s.cst_configured)
    }

    /// Transmit results wait for their `$CAXST`, likewise.
    pub(super) fn expects_xst(&self) -> bool {
        let s = &self.startup;
        s.sends_xst || (s.generation == Generation::Two && s.xst_configured)
    }

    fn set_generation(&mut self, g: Generation) {
        if self.startup.generation != g {
            tracing::info!("Micro-Modem generation: {g:?}");
            self.startup.generation = g;
        }
    }

    /// `$CAREV` with ident `INIT`: the modem (re)started and forgot its
    /// configuration and clock.
    fn modem_started(&mut self) {
        if self.startup.initializing && self.tx.active.is_none() {
            // The modem's own start-up (or the one the driver is configuring
            // after a reconnection): expected.
            tracing::info!("Micro-Modem started ($CAREV INIT): configuring it");
        } else {
            self.status(DriverStatus::ModemReset);
        }
        self.startup.awaiting = None;
        self.queue_initialization();
        // A cycle given up on the modem is gone with the reset.
        self.tx.abandoned = None;
        self.interrupt_active("the modem reset".into());
    }
}

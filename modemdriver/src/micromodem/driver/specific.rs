//! Micro-Modem specifics: requests of a `goby.acomms.protobuf.MicroModemSpecific`
//! and what the modem answers.
//!
//! | request type                        | command   | answer (reported as `DriverEvent::Specific`)   |
//! |-------------------------------------|-----------|------------------------------------------------|
//! | `MICROMODEM_TWO_WAY_PING`           | `$CCMPC`  | `$CAMPR`: one-way travel time, s (or `$CAMSG,PING_TIMEOUT`) |
//! | `MICROMODEM_MINI_DATA`              | `$CCMUC`  | — (13 bits of `mini_data`); heard: `$CAMUA`    |
//! | `MICROMODEM_FLEXIBLE_DATA`          | `$CCTDP`  | its frame asked for from the layer above; heard: `$CARDP` |
//! | `MICROMODEM_REMUS_LBL_RANGING`      | `$CCPDT`  | `$SNTTA`: travel times, s, per transponder     |
//! | `MICROMODEM_NARROWBAND_LBL_RANGING` | `$CCPNT`  | `$SNTTA`                                       |
//! | `MICROMODEM_HARDWARE_CONTROL`       | `$CCMEC`  | `$CAMER` (`MICROMODEM_HARDWARE_CONTROL_REPLY`) |
//!
//! Reports carry `time`, µs since the epoch when heard (and, for travel
//! times, the modem's own `modem_time`).
//!
//! The same jobs come from a `DRIVER_SPECIFIC` transmission (a MAC slot)
//! whose `micromodem.type` names them ([`transmission`]); an FDP slot is
//! filled like data, at most 100 bytes unless the slot says.  A
//! Micro-Modem 1 has no FDP: FDP requests and slots are refused once its
//! `$CAREV` has told the generation.

use protos::goby::acomms::protobuf::{
    micro_modem_ranging_reply::OwttAmbiguity, modem_transmission::TransmissionType,
    MicroModemHardwareControl, MicroModemRangingReply, MicroModemSpecific,
    MicroModemTransmissionType, ModemTransmission,
};

use super::super::firmware::{self, Generation};
use super::super::{fdp, ranging, transmission};
use super::machine::Machine;
use super::state::{Active, Job};
use crate::driver::{DriverEvent, SpecificReport, TransmitOutcome};

impl Machine {
    /// The job of a `MicroModemSpecific` request, or why there is none.
    pub(super) fn specific_job(&self, r: MicroModemSpecific) -> Result<Job, String> {
        use MicroModemTransmissionType as T;
        if let Some(problem) = ranging::request_problem(&r, self.modem_id as i32, &self.mm) {
            return Err(problem);
        }
        let dest = r.dest().max(0) as u32;
        Ok(match r.r#type() {
            T::MicromodemTwoWayPing => Job::Ping { dest },
            T::MicromodemMiniData => Job::Mini {
                dest,
                value: (r.mini_data() & 0x1fff) as u16,
            },
            T::MicromodemFlexibleData => {
                self.fdp_problem()?;
                let rate = r.rate.unwrap_or(1);
                if fdp::rate(rate).is_none() {
                    return Err(format!(
                        "MicroModemSpecific.rate: {rate} is not an FDP rate (1, 3 or 5)"
                    ));
                }
                Job::Fdp(Box::new(ModemTransmission {
                    src: Some(self.modem_id as i32),
                    dest: Some(r.dest.unwrap_or(-1)),
                    rate: Some(rate),
                    r#type: Some(TransmissionType::Data as i32),
                    ack_requested: Some(false),
                    ..Default::default()
                }))
            }
            T::MicromodemHardwareControl => Job::HardwareControl {
                dest,
                ctl: r.hw_ctl.unwrap_or_default(),
            },
            T::MicromodemRemusLblRanging => Job::Lbl {
                ping: ranging::remus_ping(
                    self.modem_id,
                    &ranging::merge_remus(self.mm.remus_lbl.as_ref(), r.remus_lbl.as_ref()),
                ),
                kind: T::MicromodemRemusLblRanging,
            },
            T::MicromodemNarrowbandLblRanging => Job::Lbl {
                ping: ranging::narrowband_ping(&ranging::merge_narrowband(
                    self.mm.narrowband_lbl.as_ref(),
                    r.narrowband_lbl.as_ref(),
                )),
                kind: T::MicromodemNarrowbandLblRanging,
            },
            other => return Err(format!("MicroModemSpecific.type {other:?}")),
        })
    }

    /// The job of a `DRIVER_SPECIFIC` transmission (a MAC slot, see
    /// [`transmission`]), or why there is none.
    pub(super) fn driver_specific_job(&self, mt: &ModemTransmission) -> Result<Job, String> {
        match transmission::request(mt, self.modem_id as i32, &self.mm)
            .map_err(|p| p.to_string())?
        {
            transmission::Request::Fdp(template) => {
                self.fdp_problem()?;
                Ok(Job::Fdp(Box::new(template)))
            }
            transmission::Request::Specific(request) => self.specific_job(request),
        }
    }

    /// Why no FDP packet can be sent: a Micro-Modem 1 (as its `$CAREV`
    /// told) has no Flexible Data Protocol.
    fn fdp_problem(&self) -> Result<(), String> {
        if self.startup.generation == Generation::One {
            return Err(
                "MICROMODEM_FLEXIBLE_DATA: this modem is a Micro-Modem 1, which has no Flexible \
                 Data Protocol (a Micro-Modem 2 has); use DATA slots"
                    .into(),
            );
        }
        Ok(())
    }

    fn specific(&mut self, report: MicroModemSpecific) {
        self.emit(DriverEvent::Specific(SpecificReport::new(&report)));
    }

    /// `$CAMPR`: the reply to a two-way ping (travel time, s).
    pub(super) fn ping_reply(&mut self, src: u32, dest: u32, travel_time: f64) {
        self.specific(MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemTwoWayPing as i32,
            src: Some(src as i32),
            dest: Some(dest as i32),
            ranging_reply: Some(MicroModemRangingReply {
                one_way_travel_time: vec![travel_time],
                ambiguity: Some(OwttAmbiguity::OwttExact as i32),
                is_one_way_synchronous: Some(false),
            }),
            time: Some(self.now.micros),
            ..Default::default()
        });
        if self
            .tx
            .active
            .as_ref()
            .is_some_and(|a| matches!(a.job, Job::Ping { dest } if dest == src))
        {
            self.job_progress();
            self.finish(TransmitOutcome::Sent);
        }
    }

    /// `$CAMSG,PING_TIMEOUT`: the ping under way got no reply.
    pub(super) fn ping_timeout(&mut self) {
        if self
            .tx
            .active
            .as_ref()
            .is_some_and(|a| matches!(a.job, Job::Ping { .. }))
        {
            self.finish(TransmitOutcome::Failed("no reply to the ping".into()));
        }
    }

    /// `$SNTTA`: travel times of an LBL ping (s), at the modem's `time`.
    pub(super) fn travel_times(
        &mut self,
        times: &[Option<f64>; ranging::MAX_BEACONS],
        time: String,
    ) {
        let kind = match &self.tx.active {
            Some(Active {
                job: Job::Lbl { kind, .. },
                ..
            }) => *kind,
            _ => self.tx.last_lbl,
        };
        self.specific(MicroModemSpecific {
            r#type: kind as i32,
            src: Some(self.modem_id as i32),
            ranging_reply: Some(ranging::reply(times)),
            time: Some(self.now.micros),
            modem_time: Some(time),
            ..Default::default()
        });
        if self
            .tx
            .active
            .as_ref()
            .is_some_and(|a| matches!(a.job, Job::Lbl { .. }))
        {
            self.job_progress();
            self.finish(TransmitOutcome::Sent);
        }
    }

    /// `$CAMUA`: a mini-packet heard (13 bits).
    pub(super) fn mini_packet(&mut self, src: u32, dest: u32, value: u16) {
        self.specific(MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemMiniData as i32,
            src: Some(src as i32),
            dest: Some(dest as i32),
            mini_data: Some(u32::from(value)),
            time: Some(self.now.micros),
            ..Default::default()
        });
    }

    /// `$CAMER`: the answer to a hardware line command (some firmware
    /// swaps its source and destination).
    pub(super) fn hardware_reply(&mut self, src: u32, dest: u32, line: u32, mode: u32, arg: u32) {
        let (src, dest) = if self
            .startup
            .firmware
            .as_deref()
            .is_some_and(firmware::swaps_hardware_reply)
        {
            (dest, src)
        } else {
            (src, dest)
        };
        self.specific(MicroModemSpecific {
            r#type: MicroModemTransmissionType::MicromodemHardwareControlReply as i32,
            src: Some(src as i32),
            dest: Some(dest as i32),
            hw_ctl: Some(MicroModemHardwareControl {
                line: Some(line),
                mode: Some(mode),
                arg: Some(arg),
            }),
            time: Some(self.now.micros),
            ..Default::default()
        });
    }
}

//! A `ModemTransmission` of type `DRIVER_SPECIFIC` for the Micro-Modem (a
//! MAC slot): what its `micromodem` settings ask for, checked.
//!
//! The settings are Goby3's extension
//! `[goby.acomms.micromodem.protobuf.transmission]` (number 1000 of
//! `ModemTransmission`, our field `micromodem`), so that a slot written for
//! Goby3's pAcommsHandler, e.g.
//!
//! ```text
//! slot { src: 1 rate: 1 type: DRIVER_SPECIFIC
//!        [goby.acomms.micromodem.protobuf.transmission] { type: MICROMODEM_FLEXIBLE_DATA }
//!        slot_seconds: 10 }
//! ```
//!
//! does here what it does there:
//!
//! | `micromodem.type`                   | the slot sends                                     |
//! |-------------------------------------|----------------------------------------------------|
//! | `MICROMODEM_FLEXIBLE_DATA`          | one FDP packet (`$CCTDP`) at the slot's `rate` (1, 3 or 5), filled from the queue like data: one frame of at most `max_frame_bytes`, else [`DEFAULT_FDP_SLOT_BYTES`], and never more than the rate carries |
//! | `MICROMODEM_TWO_WAY_PING`           | a ping to `dest` (`$CCMPC`)                        |
//! | `MICROMODEM_REMUS_LBL_RANGING`      | a REMUS LBL ping (`$CCPDT`), `remus_lbl` over the driver's |
//! | `MICROMODEM_NARROWBAND_LBL_RANGING` | a narrowband LBL ping (`$CCPNT`), `narrowband_lbl` over the driver's |
//! | `MICROMODEM_HARDWARE_CONTROL`       | a hardware line command to `dest` (`$CCMEC`, `hw_ctl`) |
//!
//! Others (unset, mini-packets, which need 13 bits the queue does not
//! give, and the kinds this driver does not send) are refused with the
//! field and the reason ([`request`]); `gobyd --check` refuses such slots
//! before they run.

use protos::goby::acomms::protobuf::{
    modem_transmission::TransmissionType, MicroModemConfig, MicroModemSpecific,
    MicroModemTransmissionType as T, ModemTransmission,
};

use super::{fdp, ranging};
use crate::problem::Problem;

/// Largest FDP packet from a slot that does not give `max_frame_bytes`,
/// bytes (Goby3's FDP packet size).
pub const DEFAULT_FDP_SLOT_BYTES: u32 = 100;

/// What a `DRIVER_SPECIFIC` transmission asks of the Micro-Modem.
#[derive(Debug, Clone, PartialEq)]
pub enum Request {
    /// An FDP packet: the transmission to fill (one frame of at most
    /// `max_frame_bytes`), with the slot's window, `unique_id`,
    /// destination and `ack_requested` kept.
    Fdp(ModemTransmission),
    /// A ping, an LBL ping or a hardware line command, as the request
    /// [`Driver::initiate_specific`](crate::Driver::initiate_specific) takes.
    Specific(MicroModemSpecific),
}

/// What `mt` (of type `DRIVER_SPECIFIC`, from modem `modem_id`) asks for,
/// or why it cannot be carried out: the [`Problem`]'s field is a path from
/// the transmission (`micromodem.type`, `rate`, `dest`,
/// `micromodem.remus_lbl.enable_beacons` ...). `config` gives the defaults
/// of LBL parameters.
pub fn request(
    mt: &ModemTransmission,
    modem_id: i32,
    config: &MicroModemConfig,
) -> Result<Request, Problem> {
    let settings = mt.micromodem.as_deref().cloned().unwrap_or_default();
    let kind = settings.r#type();
    let specific = |dest: Option<i32>| MicroModemSpecific {
        r#type: kind as i32,
        src: Some(modem_id),
        dest,
        ..Default::default()
    };
    let dest = mt.dest.filter(|&d| d > 0);
    let request =
        match kind {
            T::MicromodemFlexibleData => {
                let Some(rate) = fdp::rate(mt.rate()) else {
                    return Err(Problem::new(
                        "rate",
                        format!(
                        "{} is not a Flexible Data Protocol rate (1, 3 or 5), as micromodem.type \
                         MICROMODEM_FLEXIBLE_DATA needs",
                        mt.rate()
                    ),
                    ));
                };
                let bytes = mt
                    .max_frame_bytes
                    .unwrap_or(DEFAULT_FDP_SLOT_BYTES)
                    .min(rate.max_bytes());
                if bytes == 0 {
                    return Err(Problem::new(
                        "max_frame_bytes",
                        "0 leaves no room for data (leave it out for 100 bytes)",
                    ));
                }
                return Ok(Request::Fdp(ModemTransmission {
                    src: Some(modem_id),
                    max_num_frames: Some(1),
                    max_frame_bytes: Some(bytes),
                    frame: Vec::new(),
                    ..mt.clone()
                }));
            }
            T::MicromodemTwoWayPing => specific(dest),
            T::MicromodemHardwareControl => MicroModemSpecific {
                hw_ctl: settings.hw_ctl,
                ..specific(dest)
            },
            T::MicromodemRemusLblRanging => MicroModemSpecific {
                remus_lbl: settings.remus_lbl,
                ..specific(None)
            },
            T::MicromodemNarrowbandLblRanging => MicroModemSpecific {
                narrowband_lbl: settings.narrowband_lbl.clone(),
                ..specific(None)
            },
            T::MicromodemBaseType => {
                return Err(Problem::new(
                    "micromodem.type",
                    "required for a DRIVER_SPECIFIC transmission (e.g. micromodem { type: \
                 MICROMODEM_FLEXIBLE_DATA }; Goby3: [goby.acomms.micromodem.protobuf.transmission] \
                 { type: ... })",
                ))
            }
            T::MicromodemMiniData => return Err(Problem::new(
                "micromodem.type",
                "MICROMODEM_MINI_DATA is not sent from a slot (its 13 bits do not come from the \
                 queue); send mini-packets with a MicroModemSpecific request",
            )),
            other => {
                return Err(Problem::new(
                    "micromodem.type",
                    format!(
                        "{} is not a transmission this driver sends",
                        other.as_str_name()
                    ),
                ))
            }
        };
    match ranging::request_problem(&request, modem_id, config) {
        Some(problem) => Err(slot_field(&problem)),
        None => Ok(Request::Specific(request)),
    }
}

/// A problem of a `MicroModemSpecific` request
/// (`MicroModemSpecific.remus_lbl.lbl_max_range: ...`) as one of the
/// transmission it came from (`micromodem.remus_lbl.lbl_max_range`; its
/// `dest` is the transmission's).
fn slot_field(problem: &str) -> Problem {
    let rest = problem
        .strip_prefix("MicroModemSpecific")
        .unwrap_or(problem);
    let (path, reason) = match rest.strip_prefix('.').and_then(|r| r.split_once(": ")) {
        Some((path, reason)) => (path, reason),
        None => ("", rest.trim_start_matches(':').trim_start()),
    };
    let field = match path {
        "dest" => "dest".to_string(),
        "" => "micromodem".to_string(),
        path => format!("micromodem.{path}"),
    };
    Problem::new(field, reason)
}

/// Whether `mt` is a Flexible Data Protocol transmission
/// (`DRIVER_SPECIFIC` with `micromodem.type` `MICROMODEM_FLEXIBLE_DATA`).
pub fn is_fdp(mt: &ModemTransmission) -> bool {
    mt.r#type() == TransmissionType::DriverSpecific
        && mt
            .micromodem
            .as_ref()
            .is_some_and(|m| m.r#type() == T::MicromodemFlexibleData)
}

#[cfg(test)]
mod tests {
    use super::*;
    use protos::goby::acomms::protobuf::MicroModemTransmission;

    fn slot(kind: T, rate: i32) -> ModemTransmission {
        ModemTransmission {
            src: Some(1),
            dest: Some(-1),
            rate: Some(rate),
            r#type: Some(TransmissionType::DriverSpecific as i32),
            micromodem: Some(Box::new(MicroModemTransmission {
                r#type: Some(kind as i32),
                ..Default::default()
            })),
            unique_id: Some(7),
            time: Some(1_000_000),
            slot_seconds: Some(10.0),
            ..Default::default()
        }
    }

    fn ask(mt: &ModemTransmission) -> Result<Request, String> {
        request(mt, 1, &MicroModemConfig::default()).map_err(|p| p.to_string())
    }

    #[test]
    fn an_fdp_slot_is_one_frame_of_goby3s_size_unless_it_says() {
        let Ok(Request::Fdp(t)) = ask(&slot(T::MicromodemFlexibleData, 1)) else {
            panic!("an FDP request");
        };
        assert_eq!(t.max_num_frames, Some(1));
        assert_eq!(t.max_frame_bytes, Some(DEFAULT_FDP_SLOT_BYTES));
        // The slot's window, id and destination are kept.
        assert_eq!(
            (t.unique_id, t.time, t.slot_seconds, t.dest),
            (Some(7), Some(1_000_000), Some(10.0), Some(-1))
        );
        assert!(is_fdp(&t));
        // A size given is kept, up to what the rate carries.
        let mut big = slot(T::MicromodemFlexibleData, 1);
        big.max_frame_bytes = Some(150);
        assert!(matches!(ask(&big), Ok(Request::Fdp(t)) if t.max_frame_bytes == Some(150)));
        big.max_frame_bytes = Some(5000);
        assert!(matches!(ask(&big), Ok(Request::Fdp(t)) if t.max_frame_bytes == Some(192)));
        big.max_frame_bytes = Some(0);
        assert!(ask(&big).unwrap_err().starts_with("max_frame_bytes"));
    }

    #[test]
    fn refusals_name_their_field() {
        let e = ask(&slot(T::MicromodemFlexibleData, 0)).unwrap_err();
        assert!(
            e.starts_with("rate: 0 is not a Flexible Data Protocol rate"),
            "{e}"
        );
        for kind in [
            T::MicromodemBaseType,
            T::MicromodemMiniData,
            T::MicromodemFmSweep,
            T::MicromodemGenericLblRanging,
        ] {
            let e = ask(&slot(kind, 1)).unwrap_err();
            assert!(e.starts_with("micromodem.type: "), "{e}");
        }
        // A ping needs a destination; an LBL ping's parameters are the
        // slot's `micromodem`.
        let e = ask(&slot(T::MicromodemTwoWayPing, 0)).unwrap_err();
        assert!(e.starts_with("dest: required"), "{e}");
        let mut far = slot(T::MicromodemRemusLblRanging, 0);
        far.micromodem.as_mut().unwrap().remus_lbl = Some(Default::default());
        far.micromodem
            .as_mut()
            .unwrap()
            .remus_lbl
            .as_mut()
            .unwrap()
            .enable_beacons = Some(16);
        let e = ask(&far).unwrap_err();
        assert!(
            e.starts_with("micromodem.remus_lbl.enable_beacons: 16"),
            "{e}"
        );
    }

    #[test]
    fn pings_and_lbl_slots_become_specific_requests() {
        let mut ping = slot(T::MicromodemTwoWayPing, 0);
        ping.dest = Some(2);
        let Ok(Request::Specific(r)) = ask(&ping) else {
            panic!("a specific request");
        };
        assert_eq!(
            (r.r#type(), r.src, r.dest),
            (T::MicromodemTwoWayPing, Some(1), Some(2))
        );
        let lbl = slot(T::MicromodemRemusLblRanging, 0);
        assert!(matches!(ask(&lbl), Ok(Request::Specific(r))
            if r.r#type() == T::MicromodemRemusLblRanging));
        assert!(!is_fdp(&lbl));
    }
}

//! Long-baseline ranging: the `$CCPDT` (REMUS digital transponders) and
//! `$CCPNT` (narrowband transponders) commands built from their parameters,
//! and the `$SNTTA` travel times turned into a ranging reply.
//!
//! The listening time the modem is given is twice the farthest beacon's
//! range at [`ROUGH_SPEED_OF_SOUND`] plus the transponders' turn-around time,
//! as Goby's driver computes it.

use protos::goby::acomms::protobuf::{
    micro_modem_ranging_reply::OwttAmbiguity, MicroModemNarrowbandLblParams,
    MicroModemRangingReply, MicroModemRemusLblParams,
};

use super::sentence::MmSentence;

/// Speed of sound assumed for the listening time, m/s.
pub const ROUGH_SPEED_OF_SOUND: f64 = 1500.0;

/// Beacons a ping can listen to (A-D).
pub const MAX_BEACONS: usize = 4;

fn listening_ms(max_range_m: u32, turnaround_ms: u32) -> u32 {
    let round_trip = f64::from(max_range_m) * 2.0 / ROUGH_SPEED_OF_SOUND * 1000.0;
    (round_trip as u32).saturating_add(turnaround_ms)
}

/// Parameters of a request over those of the configuration (fields set in
/// `request` win).
pub fn merge_remus(
    config: Option<&MicroModemRemusLblParams>,
    request: Option<&MicroModemRemusLblParams>,
) -> MicroModemRemusLblParams {
    let mut p = config.cloned().unwrap_or_default();
    if let Some(r) = request {
        p.enable_beacons = r.enable_beacons.or(p.enable_beacons);
        p.turnaround_ms = r.turnaround_ms.or(p.turnaround_ms);
        p.lbl_max_range = r.lbl_max_range.or(p.lbl_max_range);
    }
    p
}

/// Parameters of a request over those of the configuration (fields set in
/// `request` win; its receive frequencies replace the configured ones when
/// it gives any).
pub fn merge_narrowband(
    config: Option<&MicroModemNarrowbandLblParams>,
    request: Option<&MicroModemNarrowbandLblParams>,
) -> MicroModemNarrowbandLblParams {
    let mut p = config.cloned().unwrap_or_default();
    if let Some(r) = request {
        p.transmit_freq = r.transmit_freq.or(p.transmit_freq);
        p.transmit_ping_ms = r.transmit_ping_ms.or(p.transmit_ping_ms);
        if !r.receive_freq.is_empty() {
            p.receive_freq = r.receive_freq.clone();
        }
        p.receive_ping_ms = r.receive_ping_ms.or(p.receive_ping_ms);
        p.turnaround_ms = r.turnaround_ms.or(p.turnaround_ms);
        p.transmit_flag = r.transmit_flag.or(p.transmit_flag);
        p.lbl_max_range = r.lbl_max_range.or(p.lbl_max_range);
    }
    p
}

/// `$CCPDT` for modem `src`: group 1, channel `src % 4 + 1` (the modem has
/// four), no synchronization.
pub fn remus_ping(src: u32, p: &MicroModemRemusLblParams) -> MmSentence {
    let beacons = p.enable_beacons();
    MmSentence::RemusLblPing {
        group: 1,
        channel: src % 4 + 1,
        sf: 0,
        sto: 0,
        timeout_ms: listening_ms(p.lbl_max_range(), p.turnaround_ms()),
        beacons: [0, 1, 2, 3].map(|i| beacons >> i & 1 == 1),
    }
}

/// `$CCPNT`: at most four receive frequencies, the rest 0.
pub fn narrowband_ping(p: &MicroModemNarrowbandLblParams) -> MmSentence {
    let mut receive_freq = [0; MAX_BEACONS];
    for (slot, f) in receive_freq.iter_mut().zip(&p.receive_freq) {
        *slot = *f;
    }
    MmSentence::NarrowbandLblPing {
        transmit_freq: p.transmit_freq(),
        transmit_ping_ms: p.transmit_ping_ms(),
        receive_ping_ms: p.receive_ping_ms(),
        timeout_ms: listening_ms(p.lbl_max_range(), p.turnaround_ms()),
        receive_freq,
        transmit_flag: p.transmit_flag(),
    }
}

/// How long the modem listens after a ping it was given.
pub fn listening_time(ping: &MmSentence) -> Option<std::time::Duration> {
    match ping {
        MmSentence::RemusLblPing { timeout_ms, .. }
        | MmSentence::NarrowbandLblPing { timeout_ms, .. } => {
            Some(std::time::Duration::from_millis(u64::from(*timeout_ms)))
        }
        _ => None,
    }
}

/// The ranging reply of `$SNTTA` travel times: four, of beacons A-D, NaN
/// for a beacon not heard (as Goby's driver reports it; never 0, which a
/// navigation filter would read as a range of 0 m).
pub fn reply(times: &[Option<f64>; MAX_BEACONS]) -> MicroModemRangingReply {
    MicroModemRangingReply {
        one_way_travel_time: times.iter().map(|t| t.unwrap_or(f64::NAN)).collect(),
        ambiguity: Some(OwttAmbiguity::OwttExact as i32),
        is_one_way_synchronous: Some(false),
    }
}

/// Longest listening range a long-baseline request may ask for, m: 10 km
/// is about 13 s of listening, longer than any TDMA slot in use.
pub const MAX_LBL_RANGE_M: u32 = 10_000;

/// Why a `MicroModemSpecific` request cannot be carried out as asked by
/// modem `modem_id` with the driver settings `config`, if it cannot: a
/// missing or base `type`; a ping or mini-packet without a destination
/// modem (1-127, not this one); LBL parameters (the request's over the
/// configuration's) beyond what the modem takes: beacons other than a mask
/// of A-D (1-15), more than four narrowband reply frequencies or none, no
/// narrowband transmit frequency, a listening range over
/// [`MAX_LBL_RANGE_M`]. The text names the field.
pub fn request_problem(
    r: &protos::goby::acomms::protobuf::MicroModemSpecific,
    modem_id: i32,
    config: &protos::goby::acomms::protobuf::MicroModemConfig,
) -> Option<String> {
    use protos::goby::acomms::protobuf::MicroModemTransmissionType as T;
    let range = |range: u32| {
        (range > MAX_LBL_RANGE_M).then(|| {
            format!(
                "MicroModemSpecific: lbl_max_range {range} m is over {MAX_LBL_RANGE_M} m (the modem would listen for {:.0} s)",
                f64::from(listening_ms(range, 0)) / 1000.0
            )
        })
    };
    match r.r#type() {
        T::MicromodemBaseType => Some(
            "MicroModemSpecific.type: required (MICROMODEM_TWO_WAY_PING, MICROMODEM_REMUS_LBL_RANGING, \
             MICROMODEM_NARROWBAND_LBL_RANGING, MICROMODEM_MINI_DATA, MICROMODEM_FLEXIBLE_DATA ...)"
                .into(),
        ),
        T::MicromodemTwoWayPing | T::MicromodemMiniData => match r.dest {
            Some(d) if (1..=127).contains(&d) && d != modem_id => None,
            Some(d) if d == modem_id => Some(format!(
                "MicroModemSpecific.dest: {d} is this modem; name another (1-127)"
            )),
            Some(d) => Some(format!("MicroModemSpecific.dest: {d} is not a modem id (1-127)")),
            None => Some("MicroModemSpecific.dest: required (the modem to reach, 1-127)".into()),
        },
        T::MicromodemRemusLblRanging => {
            let p = merge_remus(config.remus_lbl.as_ref(), r.remus_lbl.as_ref());
            if !(1..=15).contains(&p.enable_beacons()) {
                return Some(format!(
                    "MicroModemSpecific.remus_lbl.enable_beacons: {} is not a mask of beacons A-D (1-15)",
                    p.enable_beacons()
                ));
            }
            range(p.lbl_max_range())
        }
        T::MicromodemNarrowbandLblRanging => {
            let p = merge_narrowband(config.narrowband_lbl.as_ref(), r.narrowband_lbl.as_ref());
            if p.receive_freq.is_empty() || p.receive_freq.len() > MAX_BEACONS {
                return Some(format!(
                    "MicroModemSpecific.narrowband_lbl.receive_freq: {} given; give 1 to {MAX_BEACONS} reply frequencies (Hz)",
                    p.receive_freq.len()
                ));
            }
            if p.transmit_freq() == 0 {
                return Some(
                    "MicroModemSpecific.narrowband_lbl.transmit_freq: required (Hz), in the request or the driver's narrowband_lbl"
                        .into(),
                );
            }
            range(p.lbl_max_range())
        }
        _ => None,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn requests_that_cannot_be_carried_out_name_their_field() {
        use protos::goby::acomms::protobuf::{
            MicroModemConfig, MicroModemSpecific, MicroModemTransmissionType as T,
        };
        let config = MicroModemConfig::default();
        let ask = |r: MicroModemSpecific| request_problem(&r, 1, &config);
        let ping = |dest| MicroModemSpecific {
            r#type: T::MicromodemTwoWayPing as i32,
            dest,
            ..Default::default()
        };
        assert!(ask(MicroModemSpecific::default())
            .unwrap()
            .contains("type: required"));
        assert!(ask(ping(None)).unwrap().contains("dest: required"));
        assert!(ask(ping(Some(1))).unwrap().contains("is this modem"));
        assert!(ask(ping(Some(99999))).unwrap().contains("not a modem id"));
        assert_eq!(ask(ping(Some(2))), None);
        let remus = |beacons, range| MicroModemSpecific {
            r#type: T::MicromodemRemusLblRanging as i32,
            remus_lbl: Some(MicroModemRemusLblParams {
                enable_beacons: Some(beacons),
                lbl_max_range: Some(range),
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(ask(remus(3, 2000)), None);
        assert!(ask(remus(0, 2000)).unwrap().contains("enable_beacons: 0"));
        assert!(ask(remus(31, 2000)).unwrap().contains("enable_beacons: 31"));
        assert!(ask(remus(3, 100_000))
            .unwrap()
            .contains("lbl_max_range 100000"));
        let narrowband = |freqs: Vec<u32>, tx| MicroModemSpecific {
            r#type: T::MicromodemNarrowbandLblRanging as i32,
            narrowband_lbl: Some(MicroModemNarrowbandLblParams {
                transmit_freq: tx,
                receive_freq: freqs,
                ..Default::default()
            }),
            ..Default::default()
        };
        assert_eq!(ask(narrowband(vec![25000, 26000], Some(24000))), None);
        assert!(ask(narrowband(vec![], Some(24000)))
            .unwrap()
            .contains("0 given"));
        assert!(ask(narrowband(vec![1; 6], Some(24000)))
            .unwrap()
            .contains("6 given"));
        assert!(ask(narrowband(vec![25000], None))
            .unwrap()
            .contains("transmit_freq"));
    }

    #[test]
    fn remus_ping_from_defaults() {
        let p = merge_remus(None, None);
        // 1000 m at 1500 m/s there and back, plus 50 ms turn-around.
        let line = remus_ping(6, &p).to_line();
        assert!(line.starts_with("$CCPDT,1,3,0,0,1383,1,1,1,1*"), "{line}");
        let p = merge_remus(
            Some(&MicroModemRemusLblParams {
                enable_beacons: Some(0b0101),
                ..Default::default()
            }),
            Some(&MicroModemRemusLblParams {
                lbl_max_range: Some(1500),
                ..Default::default()
            }),
        );
        let line = remus_ping(1, &p).to_line();
        assert!(line.starts_with("$CCPDT,1,2,0,0,2050,1,0,1,0*"), "{line}");
    }

    #[test]
    fn narrowband_ping_pads_frequencies() {
        let p = merge_narrowband(
            Some(&MicroModemNarrowbandLblParams {
                transmit_freq: Some(26000),
                transmit_ping_ms: Some(5),
                receive_freq: vec![25000, 25500, 26500, 27000, 27500],
                receive_ping_ms: Some(5),
                turnaround_ms: Some(20),
                ..Default::default()
            }),
            Some(&MicroModemNarrowbandLblParams {
                receive_freq: vec![25000, 25500],
                ..Default::default()
            }),
        );
        let line = narrowband_ping(&p).to_line();
        assert!(
            line.starts_with("$CCPNT,26000,5,5,2686,25000,25500,0,0,1*"),
            "{line}"
        );
    }

    #[test]
    fn travel_times_to_reply() {
        let r = reply(&[Some(0.5), None, Some(1.25), None]);
        let t = &r.one_way_travel_time;
        assert_eq!((t.len(), t[0], t[2]), (4, 0.5, 1.25));
        assert!(t[1].is_nan() && t[3].is_nan(), "{t:?}");
    }
}

//! The NVRAM parameters an emulated Micro-Modem starts with (and returns to
//! on `$CCCFG,ALL,0`), as its configuration echo (`$CCCFQ,ALL`, and
//! `$CCCFQ,TOP` on a Micro-Modem 2) lists them.
//!
//! Names are the modem's own: the three-letter parameters that both
//! generations have (the "top level", which `TOP` lists) and a few of the
//! Micro-Modem 2's dotted group parameters (listed by `ALL` only). Values are
//! plausible factory settings for band-0 PSK at 25 kHz carrier and 5 kHz
//! bandwidth, statistics (`CST`, `XST`) and revision messages (`REV`) on;
//! `SRC` is the modem id.

/// Three-letter parameters and their starting values.
const TOP_LEVEL: &[(&str, &str)] = &[
    ("AGC", "1"),
    ("AGN", "250"),
    ("ASD", "0"),
    ("BBD", "0"),
    ("BND", "0"),
    ("BR1", "3"),
    ("BR2", "3"),
    ("BRN", "0"),
    ("BSP", "1"),
    ("BW0", "5000"),
    ("CPR", "1"),
    ("CRL", "50"),
    ("CST", "1"),
    ("CTO", "10"),
    ("DBG", "0"),
    ("DGM", "0"),
    ("DOP", "1"),
    ("DQF", "1"),
    ("DTH", "108"),
    ("DTO", "5"),
    ("DTP", "90"),
    ("ECD", "50"),
    ("EFB", "10"),
    ("EFF", "20"),
    ("FC0", "25000"),
    ("FMD", "0"),
    ("FML", "200"),
    ("GPS", "0"),
    ("HFC", "0"),
    ("IRE", "0"),
    ("MCM", "1"),
    ("MFC", "0"),
    ("MFD", "1"),
    ("MOD", "0"),
    ("MPR", "1"),
    ("MSE", "0"),
    ("MVM", "0"),
    ("NDT", "150"),
    ("NPT", "50"),
    ("NRL", "25"),
    ("NRV", "150"),
    ("PAD", "2"),
    ("PCM", "0"),
    ("POW", "-100"),
    ("PRL", "50"),
    ("PTH", "180"),
    ("PTO", "6"),
    ("REV", "1"),
    ("RXA", "0"),
    ("RXD", "1"),
    ("RXP", "1"),
    ("SCG", "0"),
    ("SGP", "0"),
    ("SHF", "0"),
    ("SNR", "0"),
    ("SNV", "0"),
    ("SRC", "1"),
    ("TAT", "50"),
    ("TOA", "0"),
    ("TXD", "200"),
    ("TXF", "1"),
    ("TXP", "1"),
    ("XST", "1"),
];

/// Dotted group parameters of the Micro-Modem 2 (listed by `ALL` only).
const GROUPS: &[(&str, &str)] = &[
    ("info.firmware_version", "2.0.27087"),
    ("info.coproc_version", "0.20.0.56"),
    ("psk.packet.mod_hdr_version", "0"),
    ("psk.rx.equalizer_ff_taps", "20"),
    ("psk.rx.equalizer_fb_taps", "10"),
    ("recv.base64data", "0"),
    ("recv.fdp_max_bytes", "2048"),
    ("xmit.pwramp_txlevel", "3"),
    ("xmit.txdelay_ms", "200"),
    ("nav.turnaround_ms", "50"),
    ("serial.main.baud", "19200"),
    ("serial.aux.baud", "19200"),
];

/// The parameters of a Micro-Modem 2 with modem id `modem_id`, in the
/// order of its echo: the three-letter ones, then the dotted ones.
pub fn micromodem2(modem_id: u32) -> Vec<(String, String)> {
    TOP_LEVEL
        .iter()
        .chain(GROUPS)
        .map(|(k, v)| {
            let v = if *k == "SRC" {
                modem_id.to_string()
            } else {
                (*v).to_string()
            };
            ((*k).to_string(), v)
        })
        .collect()
}

/// The parameters of a Micro-Modem 1 with modem id `modem_id`: the
/// three-letter ones.
pub fn micromodem1(modem_id: u32) -> Vec<(String, String)> {
    micromodem2(modem_id)
        .into_iter()
        .filter(|(k, _)| is_top_level(k))
        .collect()
}

/// Whether `key` is a three-letter (top-level) parameter, listed by
/// `$CCCFQ,TOP`.
pub fn is_top_level(key: &str) -> bool {
    !key.contains('.')
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_are_unique_and_src_is_the_id() {
        let all = micromodem2(7);
        let mut names: Vec<_> = all.iter().map(|(k, _)| k.clone()).collect();
        names.sort();
        names.dedup();
        assert_eq!(names.len(), all.len());
        assert!(all.iter().any(|(k, v)| k == "SRC" && v == "7"));
        assert!(all.iter().filter(|(k, _)| is_top_level(k)).count() >= 60);
    }
}

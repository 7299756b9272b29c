//! The modem's firmware as `$CAREV` gives it: Micro-Modem 1 or 2, and the
//! quirks of particular versions.

/// Which Micro-Modem the driver talks to.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Generation {
    /// Not yet known (no `$CAREV` and no telling configuration line).
    #[default]
    Unknown,
    /// Micro-Modem 1 (firmware 0.x / 1.x).
    One,
    /// Micro-Modem 2 (firmware 2.x and up).
    Two,
}

impl Generation {
    /// The generation of a `$CAREV` firmware version, e.g. "0.94.0.00" (1)
    /// or "2.0.16421" (2); `None` when the major number cannot be read.
    pub fn of_version(version: &str) -> Option<Generation> {
        let major: u32 = version.trim().split('.').next()?.trim().parse().ok()?;
        Some(if major >= 2 {
            Generation::Two
        } else {
            Generation::One
        })
    }

    /// What a `$CACFG` parameter name tells: Micro-Modem 2 names its newer
    /// parameters with dots (e.g. `xmit.txfrequency`).
    pub fn of_config_key(key: &str) -> Option<Generation> {
        key.contains('.').then_some(Generation::Two)
    }
}

/// A firmware version as numbers: major, minor and patch, where a fourth
/// part counts in hundredths of the patch ("0.94.0.52" is 0, 94, 52;
/// "2.0.16421" is 2, 0, 16421), as Goby's driver reads it.
pub fn version_numbers(version: &str) -> Option<(u32, u32, u32)> {
    let parts: Vec<u32> = version
        .trim()
        .split('.')
        .map(|p| p.trim().parse().ok())
        .collect::<Option<_>>()?;
    match parts.as_slice() {
        [major, minor, patch] => Some((*major, *minor, *patch)),
        [major, minor, patch, sub] => Some((*major, *minor, patch * 100 + sub)),
        _ => None,
    }
}

/// Micro-Modem 2 firmware before 2.0.18307 gives `$CAMER` with source and
/// destination swapped.
pub fn swaps_hardware_reply(version: &str) -> bool {
    matches!(version_numbers(version), Some((2, 0, patch)) if patch < 18307)
}

/// Micro-Modem 2 firmware from 2.0.26038 on gives the clock field of
/// `$CACST` (its time-of-arrival mode) as bits: the real-time clock's
/// source in bits 0-1 (2 or 3: set by the host) and the pulse-per-second
/// source in bits 2-4 (3: an external pulse); earlier firmware gives the
/// clock mode itself (0-3).
pub fn toa_mode_is_bitfield(version: &str) -> bool {
    matches!(version_numbers(version), Some((major, minor, patch))
        if major > 2 || (major == 2 && (minor > 0 || patch >= 26038)))
}

/// Micro-Modem 2 firmware before 2.0.35490 mishandles a Flexible Data
/// Protocol packet of an odd number of bytes: the host pads it with a zero
/// byte, as Goby's driver does (the layers above read trailing zeros as
/// padding).
pub fn pads_odd_fdp(version: &str) -> bool {
    matches!(version_numbers(version), Some((2, 0, patch)) if patch < 35490)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn generations() {
        assert_eq!(Generation::of_version("0.94.0.00"), Some(Generation::One));
        assert_eq!(Generation::of_version("2.0.16421"), Some(Generation::Two));
        assert_eq!(Generation::of_version("x"), None);
        assert_eq!(
            Generation::of_config_key("xmit.txfrequency"),
            Some(Generation::Two)
        );
        assert_eq!(Generation::of_config_key("SRC"), None);
    }

    #[test]
    fn versions() {
        assert_eq!(version_numbers("2.0.16421"), Some((2, 0, 16421)));
        assert_eq!(version_numbers("0.94.0.52"), Some((0, 94, 52)));
        assert_eq!(version_numbers("2.0"), None);
        assert!(swaps_hardware_reply("2.0.16421"));
        assert!(!swaps_hardware_reply("2.0.35490"));
        assert!(!swaps_hardware_reply("0.94.0.52"));
        assert!(pads_odd_fdp("2.0.27087"));
        assert!(!pads_odd_fdp("2.0.35490"));
        assert!(!pads_odd_fdp("3.1.2"));
    }
}

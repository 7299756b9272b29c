//! The emulated modems whose host interface is a byte stream, each one
//! row of [`STREAM`]: `goby modem emulate --kind` lists and starts them
//! alike (the Micro-Modem's emulator, with options of its own, and the
//! Iridium gateway's, with a command of its own, are not among them).

pub use crate::host::{Emulation, Host, Setup};

/// Every emulated modem whose host interface is a byte stream, in the
/// order they are listed.
pub static STREAM: &[Emulation] = &[
    crate::evologics::EMULATION,
    crate::popoto::EMULATION,
    crate::benthos::EMULATION,
    crate::seatrac::EMULATION,
];

/// The emulation of driver kind `kind`.
pub fn of(kind: &str) -> Option<&'static Emulation> {
    STREAM.iter().find(|e| e.kind == kind)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn each_emulation_is_of_a_driver_built_in() {
        for e in STREAM {
            assert!(
                modemdriver::built_in::by_short_name(e.kind).is_some(),
                "{}",
                e.kind
            );
            assert_eq!(of(e.kind).map(|f| f.kind), Some(e.kind));
            assert!(e.addresses.0 <= e.addresses.1);
        }
    }
}

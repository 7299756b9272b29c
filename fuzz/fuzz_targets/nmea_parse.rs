//! NMEA sentences from a WHOI Micro-Modem: arbitrary lines parse into a
//! sentence or an error, never a panic.
#![no_main]

use libfuzzer_sys::fuzz_target;
use modemdriver::micromodem::nmea::NmeaSentence;
use modemdriver::micromodem::sentence::MmSentence;

fuzz_target!(|data: &[u8]| {
    let _ = NmeaSentence::parse(data);
    let _ = MmSentence::parse(data);
});

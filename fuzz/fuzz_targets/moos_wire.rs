//! The MOOS wire format: arbitrary bytes decode into messages or packets,
//! or an error, never a panic; a decoded message encodes again.
#![no_main]

use libfuzzer_sys::fuzz_target;
use moos::wire::{decode_packet, Message};

fuzz_target!(|data: &[u8]| {
    if let Ok((message, _)) = Message::decode(data) {
        let _ = message.value();
        let mut out = Vec::new();
        let _ = message.encode_into(&mut out);
    }
    let _ = decode_packet(data);
});

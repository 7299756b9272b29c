//! Replaying arbitrary journal bytes (in memory): entries or "not a
//! journal", never a panic; replay is stable (the repaired bytes replay to
//! the same entries).
#![no_main]

use libfuzzer_sys::fuzz_target;
use queue::journal::replay_bytes;

fuzz_target!(|data: &[u8]| {
    let _ = replay_bytes(data);
    // The same bytes behind a valid header.
    let mut journal = b"GOBYJNL2".to_vec();
    journal.extend_from_slice(data);
    let replay = replay_bytes(&journal).expect("a valid header is a journal");
    assert!(replay.discarded_bytes <= data.len() as u64);
});

//! Replaying arbitrary inbox bytes (in memory): an inbox or "not an inbox",
//! never a panic; replay is stable (opening the repaired bytes again finds
//! the same pending messages and remembered identities, and nothing more
//! to discard).
#![no_main]

use std::path::Path;

use gobyd::internals::dedup::Identity;
use gobyd::internals::inbox::{Inbox, InboxEntry};
use libfuzzer_sys::fuzz_target;
use goby_store::record_log::MemoryFile;

/// Identities are remembered for 10 s from 1000 s after the epoch.
const WINDOW: u64 = 10_000_000;
const NOW: u64 = 1_000_000_000;

/// What an open inbox holds: its pending messages and remembered
/// identities (sorted).
fn live(inbox: &Inbox) -> (Vec<InboxEntry>, Vec<(Identity, u64)>) {
    let mut remembered: Vec<(Identity, u64)> =
        inbox.remembered().map(|(id, t)| (*id, t)).collect();
    remembered.sort_by_key(|(id, t)| (id.src, id.dccl_id, id.digest, *t));
    (inbox.pending(), remembered)
}

fn replay(bytes: &[u8]) {
    let file = MemoryFile::new(bytes.to_vec());
    let Ok((inbox, replay)) = Inbox::open_with(Path::new("(memory)"), file.clone(), WINDOW, NOW)
    else {
        return; // not an inbox
    };
    assert!(replay.discarded_bytes <= bytes.len());
    let first = live(&inbox);
    assert_eq!((replay.pending, replay.remembered), (first.0.len(), first.1.len()));
    drop(inbox);
    let repaired = file.contents();
    let (inbox, again) = Inbox::open_with(Path::new("(memory)"), MemoryFile::new(repaired), WINDOW, NOW)
        .expect("a repaired inbox opens");
    assert_eq!(live(&inbox), first, "re-opened, the inbox holds something else");
    assert_eq!(again.discarded_bytes, 0, "the repair left damage");
}

fuzz_target!(|data: &[u8]| {
    replay(data);
    // The same bytes behind a valid header.
    let mut inbox = b"GOBYINB1".to_vec();
    inbox.extend_from_slice(data);
    replay(&inbox);
});

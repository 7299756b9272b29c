//! Group commit of the outbox journal: many appends, one sync, and every
//! waiter (a client's `accepted` reply) released only by a sync that
//! covers its append.
//!
//! ```text
//! at most one sync under way:
//!
//! append 1, wait ── start → mark 1 ── sync ────────── finish(1): releases 1
//! append 2, wait ┐  (a sync is under way: 2 and 3 wait for the next)
//! append 3, wait ┘                                    start → mark 3 ── sync ── finish(3): releases 2, 3
//! ```
//!
//! A sync covers what was written to the file before it started: an append
//! made while a sync is under way waits for a later one. A sync starts as
//! soon as an append waits that no sync under way covers, unless the most
//! syncs allowed are under way already (the file system serves overlapping
//! syncs of one file together); whichever returns releases every waiter up
//! to its mark, in order. A lone message waits for one sync, and under load
//! each sync serves every message appended while the ones before it ran:
//! the appends per sync grow with the load, the syncs per second stay at
//! what the disk does.
//!
//! This is the bookkeeping only (sans-IO): the daemon's core appends, calls
//! [`wait`](GroupCommit::wait) with the reply, [`start`](GroupCommit::start)
//! to learn whether to start a sync (and runs it off its thread), and
//! [`finish`](GroupCommit::finish) when that sync returns, sending the
//! replies it hands back.

use std::collections::VecDeque;

/// Position in the sequence of appends that waiters wait for: a sync
/// started at mark `m` covers the appends `1..=m`.
pub type Mark = u64;

/// Waiters for the journal's sync, in the order of their appends.
#[derive(Debug)]
pub struct GroupCommit<T> {
    /// Appends waited for so far.
    written: Mark,
    /// The marks of the syncs under way, oldest first.
    syncing: VecDeque<Mark>,
    /// Most syncs under way at once.
    max_syncing: usize,
    /// Waiters with the mark of their append, oldest first.
    waiting: VecDeque<(Mark, T)>,
}

impl<T> Default for GroupCommit<T> {
    fn default() -> Self {
        Self::new(1)
    }
}

impl<T> GroupCommit<T> {
    /// Nothing written, nothing waiting; at most `max_syncing` (at least
    /// one) syncs under way at once.
    pub fn new(max_syncing: usize) -> Self {
        GroupCommit {
            written: 0,
            syncing: VecDeque::new(),
            max_syncing: max_syncing.max(1),
            waiting: VecDeque::new(),
        }
    }

    /// Registers `waiter` for an append just made (already written to the
    /// file): it is released by the first sync started after this call.
    pub fn wait(&mut self, waiter: T) {
        self.written += 1;
        self.waiting.push_back((self.written, waiter));
    }

    /// The mark of a sync to start now, if an append waits that no sync
    /// under way covers and fewer than the most syncs are under way; the
    /// caller syncs the file and calls [`finish`](Self::finish) with the
    /// mark once the sync returned.
    pub fn start(&mut self) -> Option<Mark> {
        if self.syncing.len() >= self.max_syncing {
            return None;
        }
        let newest = self.waiting.back()?.0;
        if self.syncing.back().is_some_and(|&m| m >= newest) {
            return None;
        }
        self.syncing.push_back(newest);
        Some(newest)
    }

    /// Syncs under way.
    #[cfg(test)]
    pub fn syncing(&self) -> usize {
        self.syncing.len()
    }

    /// Waiters not yet released.
    #[cfg(test)]
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    /// The sync started at `mark` returned (succeeded or failed, the
    /// caller tells its waiters which): the waiters it covers, in order
    /// (those of an earlier sync still under way included: a sync covers
    /// every append made before it started). A mark that is not under way
    /// releases nothing.
    pub fn finish(&mut self, mark: Mark) -> impl Iterator<Item = T> + '_ {
        let covered = match self.syncing.iter().position(|&m| m == mark) {
            Some(at) => {
                self.syncing.remove(at);
                self.waiting.partition_point(|(m, _)| *m <= mark)
            }
            None => 0,
        };
        self.waiting.drain(..covered).map(|(_, waiter)| waiter)
    }

    /// Every waiter, after a sync the caller made itself that covers
    /// every append (the daemon stopping); nothing is under way after.
    pub fn finish_all(&mut self) -> impl Iterator<Item = T> + '_ {
        self.syncing.clear();
        self.waiting.drain(..).map(|(_, waiter)| waiter)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_append_during_a_sync_waits_for_the_next_one() {
        let mut commit = GroupCommit::new(1);
        assert_eq!(commit.start(), None, "nothing waits");
        commit.wait("a");
        let first = commit.start().expect("a sync for a");
        // Under way: no second sync, whatever comes.
        commit.wait("b");
        commit.wait("c");
        assert_eq!(commit.start(), None);
        assert_eq!(commit.syncing(), 1);
        // The first sync covers a only.
        assert_eq!(commit.finish(first).collect::<Vec<_>>(), ["a"]);
        assert_eq!(commit.waiting(), 2);
        let second = commit.start().expect("a sync for b and c");
        commit.wait("d");
        assert_eq!(commit.finish(second).collect::<Vec<_>>(), ["b", "c"]);
        let third = commit.start().expect("a sync for d");
        assert_eq!(commit.finish(third).collect::<Vec<_>>(), ["d"]);
        assert_eq!(commit.start(), None);
        assert_eq!(commit.waiting(), 0);
    }

    #[test]
    fn a_mark_that_is_not_under_way_releases_nothing() {
        let mut commit = GroupCommit::new(1);
        commit.wait(1);
        let mark = commit.start().unwrap();
        assert_eq!(commit.finish(mark + 1).count(), 0);
        assert_eq!(commit.syncing(), 1);
        assert_eq!(commit.finish(mark).collect::<Vec<_>>(), [1]);
        // Finished once: the same mark again releases nothing more.
        commit.wait(2);
        assert_eq!(commit.finish(mark).count(), 0);
        assert_eq!(commit.waiting(), 1);
    }

    #[test]
    fn one_sync_serves_every_append_made_before_it_started() {
        let mut commit = GroupCommit::new(1);
        for i in 0..1000 {
            commit.wait(i);
        }
        let mark = commit.start().unwrap();
        assert_eq!(commit.finish(mark).count(), 1000);
    }

    #[test]
    fn overlapping_syncs_each_cover_what_was_written_before_they_started() {
        let mut commit = GroupCommit::new(2);
        commit.wait("a");
        let first = commit.start().unwrap();
        // Nothing new: no second sync.
        assert_eq!(commit.start(), None);
        commit.wait("b");
        let second = commit.start().expect("b is not covered by the first");
        commit.wait("c");
        assert_eq!(commit.start(), None, "two under way already");
        // The second returns first: it covers a and b (a sync makes
        // everything written before it started durable), not c.
        assert_eq!(commit.finish(second).collect::<Vec<_>>(), ["a", "b"]);
        let third = commit.start().expect("c");
        assert_eq!(commit.finish(first).count(), 0, "nothing left to it");
        assert_eq!(commit.finish(third).collect::<Vec<_>>(), ["c"]);
        assert_eq!(commit.syncing(), 0);
    }

    #[test]
    fn stopping_releases_everyone() {
        let mut commit = GroupCommit::new(1);
        commit.wait(1);
        commit.start().unwrap();
        commit.wait(2);
        assert_eq!(commit.finish_all().collect::<Vec<_>>(), [1, 2]);
        assert_eq!(commit.syncing(), 0);
    }
}

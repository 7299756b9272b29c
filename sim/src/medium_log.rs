//! What happened on the water of a run: every packet put on it and its
//! fate at each node that could hear it, recorded by the medium's
//! [`Observer`] ([`modemdriver::sim::observer`]).

use std::sync::Mutex;

use modemdriver::sim::observer::{Observer, Reception, Transmission};

/// Every packet of a run and every fate of one, in the order they
/// happened.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct MediumLog {
    /// Packets put on the water.
    pub transmissions: Vec<Transmission>,
    /// Each packet's fate at each node that could hear it.
    pub receptions: Vec<Reception>,
}

/// The observer of a run's medium: keeps a [`MediumLog`].
#[derive(Debug, Default)]
pub struct Recorder {
    log: Mutex<MediumLog>,
}

impl Recorder {
    /// What was recorded so far, leaving the recorder empty.
    pub fn take(&self) -> MediumLog {
        std::mem::take(&mut *self.log.lock().unwrap_or_else(|e| e.into_inner()))
    }
}

impl Observer for Recorder {
    fn transmitted(&self, transmission: &Transmission) {
        let mut log = self.log.lock().unwrap_or_else(|e| e.into_inner());
        log.transmissions.push(transmission.clone());
    }

    fn reception(&self, reception: &Reception) {
        let mut log = self.log.lock().unwrap_or_else(|e| e.into_inner());
        log.receptions.push(reception.clone());
    }
}

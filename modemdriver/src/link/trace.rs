//! Raw logging of every unit a link moves.

use std::io;

use crate::driver::{DriverEvent, EventSink, RawDirection, RawMessage};

use super::Link;

/// A [`Link`] that reports each unit received or sent as a
/// [`DriverEvent::Raw`].
#[derive(Debug)]
pub struct Tracer<L> {
    inner: L,
    sink: EventSink,
}

impl<L: Link> Tracer<L> {
    /// Wraps `inner`, reporting to `sink`.
    pub fn new(inner: L, sink: EventSink) -> Self {
        Tracer { inner, sink }
    }

    /// The wrapped link.
    pub fn get_ref(&self) -> &L {
        &self.inner
    }

    fn report(&self, direction: RawDirection, unit: &[u8], peer: &L::Peer) {
        let peer = format!("{peer:?}");
        self.sink.emit(DriverEvent::Raw(RawMessage {
            direction,
            bytes: unit.to_vec(),
            peer: (peer != "()").then_some(peer),
        }));
    }
}

impl<L: Link> Link for Tracer<L> {
    type Peer = L::Peer;

    async fn recv(&mut self) -> io::Result<(Vec<u8>, L::Peer)> {
        let (unit, peer) = self.inner.recv().await?;
        self.report(RawDirection::Incoming, &unit, &peer);
        Ok((unit, peer))
    }

    async fn send(&mut self, unit: &[u8], peer: &L::Peer) -> io::Result<()> {
        self.inner.send(unit, peer).await?;
        self.report(RawDirection::Outgoing, unit, peer);
        Ok(())
    }
}

//! Moving lines or datagrams: the device layer under every driver.
//!
//! A [`Link`] receives and sends units — a line without its delimiter, or a
//! datagram — each with the peer it came from or goes to. Wrappers compose
//! around any link: [`fault::FaultInjector`] (seeded drop, corruption,
//! truncation, garbling, delay) and [`trace::Tracer`] (raw logging as
//! [`DriverEvent::Raw`](crate::DriverEvent::Raw)).

pub mod datagram;
pub mod fault;
pub mod line;
pub mod serial;
pub mod stream;
pub mod trace;

use std::fmt::Debug;
use std::future::Future;
use std::io;

/// A device that moves units (lines or datagrams).
pub trait Link: Send {
    /// Who a unit comes from or goes to (`()` for a point-to-point line).
    type Peer: Clone + Debug + Send + Sync + 'static;

    /// Receives the next unit. Cancel-safe: if the future is dropped before it
    /// completes, no unit is lost.
    fn recv(&mut self) -> impl Future<Output = io::Result<(Vec<u8>, Self::Peer)>> + Send;

    /// Sends one unit to `peer`.
    fn send(
        &mut self,
        unit: &[u8],
        peer: &Self::Peer,
    ) -> impl Future<Output = io::Result<()>> + Send;
}

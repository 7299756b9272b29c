//! Datagrams over UDP.

use std::io;
use std::net::SocketAddr;

use tokio::net::UdpSocket;

use super::Link;

/// Largest datagram read.
pub const MAX_DATAGRAM: usize = 65_536;

/// A UDP socket as a [`Link`] whose peers are socket addresses.
#[derive(Debug)]
pub struct DatagramLink {
    socket: UdpSocket,
}

impl DatagramLink {
    /// Wraps a bound socket.
    pub fn new(socket: UdpSocket) -> Self {
        DatagramLink { socket }
    }

    /// The local address.
    pub fn local_addr(&self) -> io::Result<SocketAddr> {
        self.socket.local_addr()
    }
}

impl Link for DatagramLink {
    type Peer = SocketAddr;

    async fn recv(&mut self) -> io::Result<(Vec<u8>, SocketAddr)> {
        let mut buf = vec![0u8; MAX_DATAGRAM];
        // `recv_from` is cancel-safe.
        let (n, from) = self.socket.recv_from(&mut buf).await?;
        buf.truncate(n);
        Ok((buf, from))
    }

    async fn send(&mut self, unit: &[u8], peer: &SocketAddr) -> io::Result<()> {
        self.socket.send_to(unit, peer).await.map(|_| ())
    }
}

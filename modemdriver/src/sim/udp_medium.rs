//! The simulated water between processes: each packet goes as one UDP
//! datagram (a `goby.acomms.protobuf.SimulatorPacket`) to every peer node, and
//! times travel as wall-clock time (the processes share the machine's clock).

use std::net::SocketAddr;
use std::time::Duration;

use prost::Message;
use protos::goby::acomms::protobuf::{ModemTransmission, SimulatorPacket};
use tokio::net::UdpSocket;
use tokio::time::Instant;

use super::medium::Airborne;
use super::reception::Position;
use crate::time::now_micros;

/// A node's UDP socket and its peers.
#[derive(Debug)]
pub struct UdpMedium {
    socket: UdpSocket,
    peers: Vec<SocketAddr>,
}

impl UdpMedium {
    /// Uses `socket` to reach `peers`.
    pub fn new(socket: UdpSocket, peers: Vec<SocketAddr>) -> Self {
        UdpMedium { socket, peers }
    }

    /// Sends a packet to every peer; returns the errors met.
    pub async fn transmit(&self, packet: &Airborne) -> Vec<String> {
        let elapsed = packet.start.elapsed();
        let start = now_micros().saturating_sub(elapsed.as_micros() as u64);
        let datagram = SimulatorPacket {
            src: packet.src,
            seq: packet.seq,
            x: packet.position.x,
            y: packet.position.y,
            z: packet.position.z,
            start_micros: start,
            duration_micros: packet.duration.as_micros() as u64,
            transmission: packet.transmission.encode_to_vec(),
        }
        .encode_to_vec();
        let mut errors = Vec::new();
        for peer in &self.peers {
            if let Err(e) = self.socket.send_to(&datagram, peer).await {
                errors.push(format!("cannot send to {peer}: {e}"));
            }
        }
        errors
    }

    /// Receives the next packet (cancel-safe); `Err` describes a datagram
    /// that is not a simulator packet.
    pub async fn recv(&self) -> Result<Airborne, String> {
        let mut buf = vec![0u8; crate::link::datagram::MAX_DATAGRAM];
        let (n, from) = self
            .socket
            .recv_from(&mut buf)
            .await
            .map_err(|e| format!("UDP receive error: {e}"))?;
        let packet = SimulatorPacket::decode(&buf[..n])
            .map_err(|e| format!("datagram from {from} is not a SimulatorPacket: {e}"))?;
        let transmission =
            ModemTransmission::decode(packet.transmission.as_slice()).map_err(|e| {
                format!("SimulatorPacket.transmission from {from} is not a ModemTransmission: {e}")
            })?;
        if ![packet.x, packet.y, packet.z].iter().all(|v| v.is_finite()) {
            return Err(format!(
                "SimulatorPacket from {from}: position is not finite"
            ));
        }
        // Wall-clock start to this process's clock.
        let now = now_micros();
        let start = if packet.start_micros <= now {
            Instant::now() - Duration::from_micros(now - packet.start_micros)
        } else {
            Instant::now() + Duration::from_micros(packet.start_micros - now)
        };
        Ok(Airborne {
            src: packet.src,
            seq: packet.seq,
            position: Position::new(packet.x, packet.y, packet.z),
            start,
            duration: Duration::from_micros(packet.duration_micros),
            transmission,
            kept: false,
            garbled: false,
        })
    }
}

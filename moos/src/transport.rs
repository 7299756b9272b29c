//! Reading and writing whole packets on an async byte stream.

use std::io;

use thiserror::Error;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};

use crate::wire::{self, Message, WireError};

/// Failure to move a packet over the stream.
#[derive(Debug, Error)]
pub enum TransportError {
    /// The peer closed the connection.
    #[error("connection closed by peer")]
    Closed,
    /// The socket failed.
    #[error("socket error: {0}")]
    Io(#[from] io::Error),
    /// The bytes are not a valid packet.
    #[error("bad packet: {0}")]
    Wire(#[from] WireError),
}

/// Reads one whole packet (length prefix included) from `reader`.
pub(crate) async fn read_packet<R: AsyncRead + Unpin>(
    reader: &mut R,
) -> Result<Vec<u8>, TransportError> {
    let mut prefix = [0u8; 4];
    match reader.read_exact(&mut prefix).await {
        Ok(_) => {}
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => return Err(TransportError::Closed),
        Err(e) => return Err(e.into()),
    }
    let len = wire::packet_length(prefix)?;
    let mut packet = vec![0u8; len];
    packet[..4].copy_from_slice(&prefix);
    match reader.read_exact(&mut packet[4..]).await {
        Ok(_) => Ok(packet),
        Err(e) if e.kind() == io::ErrorKind::UnexpectedEof => Err(TransportError::Closed),
        Err(e) => Err(e.into()),
    }
}

/// Encodes `messages` as one packet and writes it to `writer`.
pub(crate) async fn write_messages<W: AsyncWrite + Unpin>(
    writer: &mut W,
    messages: &[Message],
) -> Result<(), TransportError> {
    let packet = wire::encode_packet(messages)?;
    writer.write_all(&packet).await?;
    writer.flush().await?;
    Ok(())
}

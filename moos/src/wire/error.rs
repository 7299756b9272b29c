//! Errors of encoding and decoding MOOS messages and packets.

use thiserror::Error;

/// What went wrong while encoding or decoding MOOS wire data.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum WireError {
    /// The input ended inside a field.
    #[error("truncated {field}: needs {needed} bytes, {available} left")]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Bytes the field needs.
        needed: usize,
        /// Bytes that were left.
        available: usize,
    },
    /// A length or count field holds a negative number.
    #[error("{field} is negative ({value})")]
    Negative {
        /// The field being read.
        field: &'static str,
        /// The value found.
        value: i32,
    },
    /// The message type byte is none of the MOOS message types.
    #[error("unknown message type byte 0x{0:02x}")]
    UnknownMessageKind(u8),
    /// The data type byte is none of `D`, `S`, `B`.
    #[error("unknown data type byte 0x{0:02x}")]
    UnknownDataType(u8),
    /// A text field is not valid UTF-8.
    #[error("{field} is not valid UTF-8")]
    InvalidUtf8 {
        /// The field being read.
        field: &'static str,
    },
    /// A message's length prefix disagrees with the bytes its fields occupy.
    #[error("message declares {declared} bytes but its fields occupy {used}")]
    MessageLength {
        /// Length from the message's prefix.
        declared: usize,
        /// Bytes its fields actually used.
        used: usize,
    },
    /// A packet's length prefix is below the header size or above [`super::MAX_PACKET_LEN`].
    #[error("packet length {length} is outside {min}..={max} bytes")]
    PacketLength {
        /// Length from the packet's prefix.
        length: i64,
        /// Smallest valid packet.
        min: usize,
        /// Largest packet accepted.
        max: usize,
    },
    /// A packet's length prefix disagrees with the bytes given to the decoder.
    #[error("packet declares {declared} bytes but {actual} were given")]
    PacketSize {
        /// Length from the packet's prefix.
        declared: usize,
        /// Bytes given.
        actual: usize,
    },
    /// The packet is flagged as compressed, which MOOS V10 never sends.
    #[error("packet compression flag is {0}; compressed packets are not part of MOOS V10")]
    Compressed(u8),
    /// Bytes are left over after the packet's last message.
    #[error("packet has {0} bytes after its last message")]
    TrailingBytes(usize),
    /// A message inside a packet failed to decode.
    #[error("message {index} of packet: {source}")]
    InMessage {
        /// Zero-based position of the message in the packet.
        index: usize,
        /// What was wrong with it.
        source: Box<WireError>,
    },
    /// A value is too large for the 32-bit lengths of the wire format.
    #[error("{field} is {length} bytes, more than the wire format allows")]
    TooLong {
        /// The field being written.
        field: &'static str,
        /// Its length.
        length: usize,
    },
    /// The connection preamble names another protocol.
    #[error(
        "peer speaks protocol {announced:?}, not MOOS V10 ({:?})",
        super::PROTOCOL_NAME
    )]
    WrongProtocol {
        /// What the peer announced.
        announced: String,
    },
}

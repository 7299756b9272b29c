//! Errors of the queuing layer; each names the message type (and field) at fault.

/// What went wrong in the queuing layer.
#[derive(Debug, thiserror::Error)]
pub enum QueueError {
    /// A queue configuration entry is not valid.
    #[error("invalid queue configuration for {message}: {reason}")]
    Config {
        /// The message type named by the entry.
        message: String,
        /// What is wrong.
        reason: String,
    },
    /// A message was pushed (or received) whose type has no queue.
    #[error("no queue is configured for {0}: configure it first")]
    NotConfigured(String),
    /// A message is larger than the largest frame the link carries.
    #[error("{message} encodes to {size} bytes, more than the largest frame ({max} bytes)")]
    TooLarge {
        /// The message type.
        message: String,
        /// Its encoded size.
        size: usize,
        /// The largest frame.
        max: usize,
    },
    /// A role (source, destination, time) could not be read from a message.
    #[error("{message}: {role} role (field {field}): {reason}")]
    Role {
        /// The message type.
        message: String,
        /// Which role.
        role: &'static str,
        /// The field path of the role.
        field: String,
        /// What is wrong.
        reason: String,
    },
    /// A data request cannot be answered as given.
    #[error("data request: {0}")]
    Request(String),
    /// A received frame (numbered within its transmission) did not decode.
    #[error("received frame {frame}: {source}")]
    Frame {
        /// Index of the frame in the transmission.
        frame: usize,
        /// The DCCL error.
        source: dccl::Error,
    },
    /// An error of the DCCL codec (encoding a pushed message, ...).
    #[error(transparent)]
    Dccl(#[from] dccl::Error),
}

/// Result of the queuing layer.
pub type Result<T, E = QueueError> = std::result::Result<T, E>;

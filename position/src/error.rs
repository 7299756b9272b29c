//! Errors of the position telemetry codec.

/// What went wrong.
#[derive(Debug, thiserror::Error)]
pub enum PositionError {
    /// Invalid parameters.
    #[error("position config: {0}")]
    Config(String),
    /// A sample that cannot be transmitted (outside the configured bounds, not finite, ...).
    #[error("position sample: {0}")]
    Sample(String),
    /// A frame that cannot be encoded or decoded.
    #[error("position frame: {0}")]
    Frame(String),
    /// The DCCL layer refused a message.
    #[error(transparent)]
    Dccl(#[from] dccl::Error),
    /// The arithmetic coder refused a model or ran out of bits.
    #[error(transparent)]
    Codec(#[from] dccl::CodecError),
    /// A trajectory file that cannot be read.
    #[error("{0}")]
    Trajectory(String),
}

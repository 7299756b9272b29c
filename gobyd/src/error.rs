//! Why the daemon could not start or had to stop.

pub use crate::config::ConfigError;
pub use crate::core::data_dir::DataDirError;
pub use crate::core::outbox::OutboxError;

/// Why the daemon could not start or had to stop.
#[derive(Debug, thiserror::Error)]
pub enum DaemonError {
    /// The configuration is not usable.
    #[error(transparent)]
    Config(#[from] ConfigError),
    /// The data directory could not be created, or another daemon holds it.
    #[error(transparent)]
    DataDir(#[from] DataDirError),
    /// The queue or its journal could not be set up.
    #[error("outgoing queue: {0}")]
    Outbox(#[from] OutboxError),
    /// The queue configuration is not valid.
    #[error("queue: {0}")]
    Queue(#[from] queue::QueueError),
    /// The medium access control configuration is not valid.
    #[error("mac: {0}")]
    Mac(#[from] amac::AmacError),
    /// The modem driver could not start.
    #[error("driver: {0}")]
    Driver(#[from] modemdriver::DriverError),
    /// A file or socket could not be opened.
    #[error("{context}: {source}")]
    Io {
        /// What was being done.
        context: String,
        /// The I/O error.
        source: std::io::Error,
    },
}

pub(crate) fn io_error(context: impl Into<String>) -> impl FnOnce(std::io::Error) -> DaemonError {
    let context = context.into();
    move |source| DaemonError::Io { context, source }
}

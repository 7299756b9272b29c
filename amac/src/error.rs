//! Errors of the medium access control.

use thiserror::Error;

/// Full name of the configuration message, used in error texts.
pub const MAC_CONFIG_NAME: &str = "goby.acomms.protobuf.MACConfig";

/// A configuration that the medium access control cannot run.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum AmacError {
    /// A field of the configuration has a value that cannot be used.
    #[error("{message}.{field}: {reason}")]
    InvalidField {
        /// Full name of the message holding the field.
        message: &'static str,
        /// Path of the field inside the message, e.g. `slot[2].slot_seconds`.
        field: String,
        /// What is wrong with it.
        reason: String,
    },
    /// An operation that the configured scheme does not support.
    #[error("{operation} is not available with the {scheme} scheme")]
    WrongScheme {
        /// What was asked.
        operation: &'static str,
        /// Name of the configured scheme.
        scheme: &'static str,
    },
    /// A `MACUpdate` for another node's cycle.
    #[error("the MACUpdate is for modem {dest}, not for this node (modem {modem_id})")]
    NotForThisNode {
        /// The update's `dest`.
        dest: i32,
        /// This node's modem id.
        modem_id: i32,
    },
}

impl AmacError {
    /// An [`AmacError::InvalidField`] of [`MAC_CONFIG_NAME`].
    pub fn config_field(field: impl Into<String>, reason: impl Into<String>) -> Self {
        AmacError::InvalidField {
            message: MAC_CONFIG_NAME,
            field: field.into(),
            reason: reason.into(),
        }
    }
}

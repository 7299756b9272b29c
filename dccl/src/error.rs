//! Errors of the DCCL library.

use std::fmt;

/// Where in a message an error happened: the message's full name and, when
/// known, the dotted path of the field.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Location {
    /// Full name of the root message (e.g. `goby.example.NavigationReport`).
    pub message: String,
    /// Path of the field inside the message (e.g. `pos.x`), empty for the message itself.
    pub field: String,
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.message.is_empty() && self.field.is_empty() {
            f.write_str("message type not known")
        } else if self.field.is_empty() {
            write!(f, "message {}", self.message)
        } else {
            write!(f, "message {}, field {}", self.message, self.field)
        }
    }
}

/// Every error the library returns. Each names the message and, where it
/// applies, the field. More kinds may be added: a `match` needs a `_` arm.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// A `.proto` file could not be read or compiled. The text starts
    /// `path:LINE:COLUMN: ` (1-based) when the fault has a place in a file.
    #[error("{0}")]
    Proto(String),
    /// A message type is not valid for DCCL (missing option, bad bounds, too large, ...).
    #[error("invalid DCCL definition ({location}): {reason}")]
    Definition {
        /// Message and field at fault.
        location: Location,
        /// What is wrong.
        reason: String,
    },
    /// Two loaded types claim the same DCCL id.
    #[error("DCCL id {id} of {new} is already used by {existing}")]
    DuplicateId {
        /// The id in question.
        id: u32,
        /// The type already loaded with that id.
        existing: String,
        /// The type that was being loaded.
        new: String,
    },
    /// The message type (by name) has not been loaded.
    #[error("message type {0} has not been loaded")]
    UnknownType(String),
    /// The DCCL id read from the bytes belongs to no loaded type.
    #[error("message id {0} has not been loaded")]
    UnknownId(u32),
    /// A codec model (e.g. an arithmetic model) is invalid.
    #[error("invalid model `{name}`: {reason}")]
    InvalidModel {
        /// Name of the model.
        name: String,
        /// What is wrong.
        reason: String,
    },
    /// A value could not be encoded (strict mode: out of range; or a missing required field).
    #[error("cannot encode ({location}): {reason}")]
    Encode {
        /// Message and field at fault.
        location: Location,
        /// What is wrong.
        reason: String,
    },
    /// The header of an encrypted message was read but its body could not
    /// be: the body was most likely encrypted with another passphrase (or
    /// the message is truncated or not a DCCL message).
    #[error(
        "cannot decode (message {message}): likely wrong passphrase \
         (the header decodes but the body does not: {reason})"
    )]
    WrongPassphrase {
        /// Full name of the message type read from the header.
        message: String,
        /// The error met in the body.
        reason: String,
    },
    /// Bytes could not be decoded (truncated, garbage, unknown id...).
    #[error("cannot decode ({location}): {reason}")]
    Decode {
        /// Message and field at fault.
        location: Location,
        /// What is wrong.
        reason: String,
    },
}

impl Error {
    /// Builds a [`Error::Definition`].
    pub fn definition(message: &str, field: &str, reason: impl Into<String>) -> Self {
        Error::Definition {
            location: Location {
                message: message.to_string(),
                field: field.to_string(),
            },
            reason: reason.into(),
        }
    }
}

/// Result alias of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// An error raised inside a field codec, before the message codec adds the
/// message name and the field path to it. Built with [`CodecError::new`];
/// more fields may be added.
#[derive(Debug, Clone, PartialEq, Eq)]
#[non_exhaustive]
pub struct CodecError {
    /// Dotted path of the field, filled in as the error travels up the message tree.
    pub field: String,
    /// What went wrong.
    pub reason: String,
}

impl CodecError {
    /// A new error with no field path yet.
    pub fn new(reason: impl Into<String>) -> Self {
        CodecError {
            field: String::new(),
            reason: reason.into(),
        }
    }

    /// Prefixes the field path with `name` (called by the enclosing message codec).
    pub fn in_field(mut self, name: &str) -> Self {
        if self.field.is_empty() {
            self.field = name.to_string();
        } else {
            self.field = format!("{name}.{}", self.field);
        }
        self
    }

    pub(crate) fn into_encode(self, message: &str) -> Error {
        Error::Encode {
            location: Location {
                message: message.to_string(),
                field: self.field,
            },
            reason: self.reason,
        }
    }

    pub(crate) fn into_decode(self, message: &str) -> Error {
        Error::Decode {
            location: Location {
                message: message.to_string(),
                field: self.field,
            },
            reason: self.reason,
        }
    }

    pub(crate) fn into_definition(self, message: &str) -> Error {
        Error::Definition {
            location: Location {
                message: message.to_string(),
                field: self.field,
            },
            reason: self.reason,
        }
    }
}

impl fmt::Display for CodecError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        if self.field.is_empty() {
            f.write_str(&self.reason)
        } else {
            write!(f, "field {}: {}", self.field, self.reason)
        }
    }
}

impl std::error::Error for CodecError {}

//! Decoding a byte string that holds one or more DCCL messages back to back
//! (a modem frame of stitched messages), with an error that says where the
//! bytes stopped being a message. A frame gobyd sent ends with its
//! identity trailer (`goby.acomms.protobuf.FrameIdentity`, see
//! `queue::identity`): the messages end there.

use dccl::Codec;
use prost_reflect::DynamicMessage;

use crate::lines::LineError;

/// Decodes byte strings of messages back to back.
pub(crate) struct FrameDecoder<'a> {
    /// The codec with the types loaded.
    pub codec: &'a Codec,
    /// Decode every message as this type rather than by its id (needed for
    /// `omit_id` types).
    pub as_type: Option<&'a str>,
    /// A passphrase is set: leftover bytes may come from a wrong one.
    pub encrypted: bool,
}

/// Why decoding a byte string stopped.
pub(crate) enum FrameError {
    /// The bytes from `offset` (from 0) on are not a message.
    Bad {
        /// Where the message that failed starts.
        offset: usize,
        /// How many bytes are left from there.
        left: usize,
        /// The bytes end inside the message (it may go on elsewhere).
        truncated: bool,
        /// The error, worded for the user.
        text: String,
    },
    /// A decoded message could not be written.
    Output(LineError),
}

impl FrameError {
    /// `byte K: <error> (N byte(s) left undecoded)`, or the output error.
    pub(crate) fn describe(&self) -> String {
        match self {
            FrameError::Bad {
                offset, left, text, ..
            } => format!("byte {offset}: {text} ({left} byte(s) left undecoded)"),
            FrameError::Output(LineError::Bad(e)) => e.clone(),
            FrameError::Output(LineError::Fatal(e)) => e.to_string(),
        }
    }
}

impl FrameDecoder<'_> {
    /// The hint added to an id that names no loaded type: the bytes may be
    /// a message of a type with `omit_id`, which only `-m` can decode.
    fn omit_id_hint(&self) -> String {
        let omitting: Vec<String> = self
            .codec
            .loaded()
            .into_iter()
            .filter(|n| self.codec.omits_id(n).unwrap_or(false))
            .collect();
        let mut hint = String::from(
            " (a message with omit_id: true carries no id on the wire: name its type with -m",
        );
        if !omitting.is_empty() {
            hint.push_str(&format!("; loaded with omit_id: {}", omitting.join(", ")));
        }
        hint.push(')');
        hint
    }

    /// Decodes every message of `bytes`, handing each to `emit`. The first
    /// message that cannot be decoded ends the string.
    pub(crate) fn decode(
        &self,
        bytes: &[u8],
        mut emit: impl FnMut(&DynamicMessage) -> Result<(), LineError>,
    ) -> Result<(), FrameError> {
        let trailer = queue::TrailerCodec::new();
        let mut offset = 0usize;
        while offset < bytes.len() {
            let rest = &bytes[offset..];
            // gobyd's identity trailer after the messages (unless the
            // user's own types take its id).
            if offset > 0
                && self.as_type.is_none()
                && trailer.starts_trailer(rest)
                && trailer.decode(rest).is_some()
                && !self
                    .codec
                    .loaded()
                    .iter()
                    .any(|n| self.codec.id_of(n).ok() == Some(queue::identity::DCCL_ID))
            {
                break;
            }
            let options = dccl::DecodeOptions {
                as_type: self.as_type,
            };
            match self.codec.decode_with(rest, &options) {
                Ok(dccl::Decoded {
                    message: msg,
                    len: used,
                }) => {
                    emit(&msg).map_err(FrameError::Output)?;
                    if used == 0 {
                        break;
                    }
                    offset += used;
                }
                Err(e) => {
                    let mut text = match &e {
                        dccl::Error::Decode { location, reason } if location.message.is_empty() => {
                            format!("cannot decode: {reason}")
                        }
                        other => other.to_string(),
                    };
                    if self.as_type.is_none()
                        && (matches!(e, dccl::Error::UnknownId(_))
                            || text.contains("cannot read the DCCL id"))
                    {
                        text.push_str(&self.omit_id_hint());
                    }
                    // The library names a body that does not decode under a
                    // clear header; a message after the first may have started
                    // in the wrong place because the one before was misread.
                    // Without a passphrase, an encrypted body reads as
                    // garbage: too short, a bad value, or of another
                    // length, so that the next message starts in the wrong
                    // place (its id unknown).
                    if !self.encrypted
                        && (matches!(e, dccl::Error::Decode { .. })
                            || (offset > 0 && matches!(e, dccl::Error::UnknownId(_))))
                        && !text.contains("passphrase")
                    {
                        text.push_str(
                            " (if the sender encrypted its messages, give the same --passphrase)",
                        );
                    }
                    if self.encrypted && offset > 0 && !text.contains("passphrase") {
                        text.push_str(
                            " (likely a wrong passphrase: the body of the message before \
                             decodes to another length)",
                        );
                    }
                    return Err(FrameError::Bad {
                        offset,
                        left: rest.len(),
                        truncated: text.contains("truncated")
                            && !matches!(e, dccl::Error::WrongPassphrase { .. }),
                        text,
                    });
                }
            }
        }
        Ok(())
    }
}

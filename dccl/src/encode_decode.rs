//! What [`Codec::encode`](crate::Codec::encode) and
//! [`Codec::decode`](crate::Codec::decode) take and give besides bytes: the
//! kinds of message encoding takes ([`Encodable`]), and the options and
//! results of [`Codec::encode_with`](crate::Codec::encode_with) and
//! [`Codec::decode_with`](crate::Codec::decode_with).

use std::any::Any;

use prost_reflect::{DynamicMessage, MessageDescriptor, ReflectMessage};

use crate::changes::ValueChange;

/// A message [`Codec::encode`](crate::Codec::encode) takes: a
/// `DynamicMessage`, a prost-generated struct deriving `ReflectMessage` (its
/// type is the one its descriptor names), or a message given as its
/// protobuf bytes ([`Protobuf`]). All three give the same DCCL bytes for
/// the same message.
///
/// Sealed: the codec reads each kind its own way.
pub trait Encodable: sealed::Sealed {
    #[doc(hidden)]
    fn input(&self) -> sealed::Input<'_>;
}

/// A message given as its protobuf encoding (as any protobuf library writes
/// it) with the full name of its loaded type: [`Codec::encode`](crate::Codec::encode)
/// encodes it without decoding it to a `DynamicMessage` first when the
/// type's codecs allow it (every message field coded by the default message
/// codec). Unknown fields are ignored, as for a `DynamicMessage`. Bytes that
/// are not a protobuf message of the type are an
/// [`Error::Encode`](crate::Error::Encode) ("not a valid protobuf message of
/// that type").
#[derive(Debug, Clone, Copy)]
pub struct Protobuf<'a> {
    /// The full name of the message type, e.g. `goby.example.Status`.
    pub full_name: &'a str,
    /// The message's protobuf wire bytes.
    pub bytes: &'a [u8],
}

impl<'a> Protobuf<'a> {
    /// The message of type `full_name` whose protobuf encoding is `bytes`.
    pub fn new(full_name: &'a str, bytes: &'a [u8]) -> Self {
        Protobuf { full_name, bytes }
    }
}

pub(crate) mod sealed {
    use super::*;

    pub trait Sealed {}

    /// How the codec reads an [`Encodable`].
    pub enum Input<'a> {
        Dynamic(&'a DynamicMessage),
        /// A prost-generated struct, as its descriptor and protobuf bytes.
        Typed(MessageDescriptor, Vec<u8>),
        Protobuf(Protobuf<'a>),
    }
}

impl<T: ReflectMessage + 'static> sealed::Sealed for T {}

impl<T: ReflectMessage + 'static> Encodable for T {
    fn input(&self) -> sealed::Input<'_> {
        match (self as &dyn Any).downcast_ref::<DynamicMessage>() {
            Some(msg) => sealed::Input::Dynamic(msg),
            None => sealed::Input::Typed(self.descriptor(), self.encode_to_vec()),
        }
    }
}

impl sealed::Sealed for Protobuf<'_> {}

impl Encodable for Protobuf<'_> {
    fn input(&self) -> sealed::Input<'_> {
        sealed::Input::Protobuf(*self)
    }
}

/// How [`Codec::encode_with`](crate::Codec::encode_with) encodes; the
/// default encodes as [`Codec::encode`](crate::Codec::encode) does.
#[derive(Debug, Clone, Default)]
pub struct EncodeOptions {
    /// Report every value the codec changes on the way in
    /// [`Encoded::changes`]: out-of-range numbers sent as "not present",
    /// NaN sent as the minimum, strings, bytes and arrays truncated,
    /// undefined enum values. The bytes are the same either way; in strict
    /// mode the first such value is an error instead.
    pub changes: bool,
}

impl EncodeOptions {
    /// Options that report the values the codec changes
    /// ([`EncodeOptions::changes`]).
    pub fn with_changes() -> Self {
        EncodeOptions { changes: true }
    }
}

/// What [`Codec::encode_with`](crate::Codec::encode_with) wrote besides the
/// bytes it appended.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Encoded {
    /// The number of bytes appended: the message's encoded size.
    pub len: usize,
    /// The values the codec changed, in encoding order (empty unless
    /// [`EncodeOptions::changes`]).
    pub changes: Vec<ValueChange>,
}

/// How [`Codec::decode_with`](crate::Codec::decode_with) decodes; the
/// default decodes as [`Codec::decode`](crate::Codec::decode) does, the
/// type found by the DCCL id at the start of the bytes.
#[derive(Debug, Clone, Copy, Default)]
pub struct DecodeOptions<'a> {
    /// Decode as this loaded type (its full name): the only way to decode a
    /// type with `omit_id`; for other types the id read must be that
    /// type's, or the decoding is an [`Error::Decode`](crate::Error::Decode)
    /// ("received id …, expected …").
    pub as_type: Option<&'a str>,
}

impl<'a> DecodeOptions<'a> {
    /// Options that decode as the loaded type `full_name`
    /// ([`DecodeOptions::as_type`]).
    pub fn as_type(full_name: &'a str) -> Self {
        DecodeOptions {
            as_type: Some(full_name),
        }
    }
}

/// A message [`Codec::decode_with`](crate::Codec::decode_with) decoded, with
/// its length.
#[derive(Debug, Clone, PartialEq)]
pub struct Decoded {
    /// The message.
    pub message: DynamicMessage,
    /// The number of bytes it took: where the next message of a frame starts.
    pub len: usize,
}

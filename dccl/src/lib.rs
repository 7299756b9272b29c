//! # DCCL — Dynamic Compact Control Language
//!
//! Packs protobuf messages into the fewest bits their declared bounds allow,
//! for links that carry a few dozen bytes at a time (acoustic modems,
//! satellite, low-rate radio). Messages are ordinary `.proto` files annotated
//! with `(dccl.msg)` and `(dccl.field)` options; the encoding is byte for byte
//! that of the reference C++ library (libdccl 4), codec versions 2, 3 and 4.
//!
//! Message types come from `.proto` files compiled at run time
//! ([`compile_protos`]) or from prost-generated structs that derive
//! `prost_reflect::ReflectMessage` ([`Codec::load_type`]); both go through the
//! same code.
//!
//! ```
//! use dccl::Codec;
//! use prost_reflect::DynamicMessage;
//!
//! // A program embedding dccl: compile its message definitions...
//! let pool = dccl::compile_sources(&[(
//!     "ping.proto",
//!     r#"syntax = "proto2";
//!        import "dccl/option_extensions.proto";
//!        package demo;
//!        message Ping {
//!          option (dccl.msg) = { id: 20 max_bytes: 16 codec_version: 4 };
//!          required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
//!          optional double range = 2 [(dccl.field) = { min: 0 max: 5000 precision: 1 }];
//!          optional string note = 3 [(dccl.field).max_length = 8];
//!        }"#,
//! )])?;
//! let desc = pool.get_message_by_name("demo.Ping").unwrap();
//!
//! // ...load them into a codec...
//! let mut codec = Codec::new();
//! codec.load(&desc)?;
//! assert_eq!(codec.max_size("demo.Ping")?, 13);
//!
//! // ...and encode and decode.
//! let msg = DynamicMessage::parse_text_format(desc, r#"src: 3 range: 1234.56 note: "hi""#)?;
//! let bytes = codec.encode(&msg)?;
//! assert_eq!(bytes.len(), 7); // 2 header bytes (id, src) + 37 body bits
//! let back = codec.decode(&bytes)?;
//! assert_eq!(back.get_field_by_name("range").unwrap().as_f64(), Some(1234.6));
//!
//! // Several messages in one frame decode one after the other.
//! let mut frame = bytes.clone();
//! frame.extend(&bytes);
//! assert_eq!(codec.decode_all(&frame)?.len(), 2);
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

//!
//! ## Agreement with libdccl 4.2
//!
//! Fields (and `oneof`s) are coded, sized, hashed and listed in the order
//! they are declared in the `.proto` file, at every level of nesting. Values
//! that do not fit are changed as libdccl changes them (out of range: not
//! present; NaN: the minimum; strings and arrays: truncated);
//! [`Codec::encode_with`] (with [`EncodeOptions::changes`]) and [`Codec::check`] list every such
//! change ([`ValueChange`]), and strict mode ([`Codec::set_strict`]) refuses
//! them. [`Codec::load_valid_messages`] loads every valid DCCL message of a
//! file that also holds helper types and reports the others with the reason.
//! `.proto` sources with brackets nested deeper than 100 levels are refused
//! before parsing.
//!
//! ## Dynamic conditions
//!
//! `(dccl.field).dynamic_conditions` (`required_if`, `omit_if`, `only_if`,
//! `min`, `max`), scripts in Lua over the message being coded, are
//! evaluated as libdccl 4.2 built with Lua evaluates them, by an evaluator
//! of this crate for the part of Lua 5.3 conditions are written in (no C
//! compiler, no Lua); a script outside it is refused when its message is
//! loaded, one that fails is an error naming the message, the field and the
//! script. [`Codec::condition_outcomes`] tells what each gave.
//!
//! ## What is public
//!
//! The crate root holds what a program embedding DCCL uses: [`Codec`] and
//! what its methods take and return, the errors, the `.proto` loaders,
//! [`ArithmeticModel`] and [`ArithmeticState`], and the text form of
//! messages as libdccl's tools print it ([`short_debug_string`]). Writing a
//! codec of your own takes the lower-level items of [`field`]: the
//! [`FieldCodec`] trait, the bit buffers, the encode and decode contexts,
//! the `(dccl.field)` options, the built-in message codec and the integer
//! arithmetic coder.

#![warn(missing_docs)]

mod analyze;
mod bits;
mod changes;
mod codec;
mod codecs;
mod conditions;
mod crypto;
mod definition_hash;
mod encode_decode;
mod error;
pub mod field;
mod field_codec;
mod loader;
mod nesting;
mod options;
mod registry;
mod rounding;
mod text_format;
mod wire;

pub use changes::ValueChange;
pub use codec::{Codec, FieldSize, FileLoad, SkippedType};
pub use codecs::arithmetic::{ArithmeticModel, ArithmeticState};
pub use conditions::{lua52_difference, ConditionOutcome, DefinitionWarning};
pub use encode_decode::{DecodeOptions, Decoded, Encodable, EncodeOptions, Encoded, Protobuf};
pub use error::{CodecError, Error, Location, Result};
pub use field_codec::{DateShift, FieldCodec, FieldCodecFactory, FieldSpec, MessagePart};
pub use loader::{compile_protos, compile_sources, pool_file_name};
pub use registry::CodecRegistry;
pub use text_format::{debug_string, double_to_text, float_to_text, short_debug_string};

pub use prost_reflect;

/// The crate's README.md, whose examples run as doctests.
#[cfg(doctest)]
#[doc = include_str!("../README.md")]
struct ReadmeDoctests;

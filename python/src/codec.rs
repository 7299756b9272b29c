//! `dccl._dccl.Codec`: the `dccl` crate's codec over serialized protobuf
//! messages. The Python package wraps it to take and return
//! `google.protobuf` message objects (`dccl/__init__.py`); every value
//! crosses the boundary as the message's protobuf wire bytes, so no logic of
//! the codec lives here.

use dccl::prost_reflect::{
    DeserializeOptions, DynamicMessage, MessageDescriptor, ReflectMessage, SerializeOptions,
};
use prost::Message;
use pyo3::exceptions::PyLookupError;
use pyo3::prelude::*;
use pyo3::types::PyBytes;

use crate::errors::{to_py, DcclException, DcclOutOfRangeException};
use crate::pool;

/// Values changed by encoding, as `(field path, reason)` pairs.
type Changes = Vec<(String, String)>;

fn pairs(changes: Vec<dccl::ValueChange>) -> Changes {
    changes.into_iter().map(|c| (c.field, c.reason)).collect()
}

/// A DCCL codec: load message types by full name, then encode and decode
/// them. Messages go in and out as `(full name, protobuf wire bytes)`.
#[pyclass(module = "dccl._dccl", name = "Codec")]
pub struct Codec {
    inner: dccl::Codec,
    strict: bool,
}

impl Codec {
    /// The descriptor of a type this codec has loaded, else of the pool.
    fn descriptor(&self, name: &str) -> PyResult<MessageDescriptor> {
        self.inner
            .descriptor(name)
            .or_else(|| pool::message(name))
            .ok_or_else(|| to_py(dccl::Error::UnknownType(name.to_string())))
    }

    fn parse(&self, name: &str, data: &[u8]) -> PyResult<DynamicMessage> {
        let desc = self.descriptor(name)?;
        DynamicMessage::decode(desc, data).map_err(|e| {
            DcclException::new_err(format!(
                "cannot encode (message {name}): not a valid protobuf message of that type: {e}"
            ))
        })
    }

    /// Encodes, reporting the values the codec changed (as `(field path,
    /// reason)`); in strict mode an error that the lenient codec would not
    /// raise is a value out of its bounds: `DcclOutOfRangeException`.
    fn encode_checked(&self, msg: &DynamicMessage) -> PyResult<(Vec<u8>, Changes)> {
        match self.inner.encode_with_changes(msg) {
            Ok((bytes, mut changes)) => {
                changes.extend(self.inner.moved_dates(msg).map_err(to_py)?);
                Ok((bytes, pairs(changes)))
            }
            Err(e) => {
                if self.strict && matches!(e, dccl::Error::Encode { .. }) {
                    let mut lenient = self.inner.clone();
                    lenient.set_strict(false);
                    if lenient.encode(msg).is_ok() {
                        return Err(DcclOutOfRangeException::new_err(e.to_string()));
                    }
                }
                Err(to_py(e))
            }
        }
    }

    /// One message from `data`: found by its id, or with `name` decoded
    /// as that loaded type.
    fn decode_one(&self, data: &[u8], name: Option<&str>) -> PyResult<DynamicMessage> {
        match name {
            None => self.inner.decode(data).map_err(|e| {
                // Bytes of a type that sends no id read as some other id.
                let omitting: Vec<String> = self
                    .inner
                    .loaded()
                    .into_iter()
                    .filter(|n| self.inner.omits_id(n).unwrap_or(false))
                    .collect();
                match (&e, omitting.first()) {
                    (dccl::Error::UnknownId(_), Some(first)) => DcclException::new_err(format!(
                        "{e}; a type with omit_id: true sends no id ({}): decode its \
                         messages by their type, e.g. decode(data, \"{first}\")",
                        omitting.join(", ")
                    )),
                    _ => to_py(e),
                }
            }),
            Some(name) => self
                .inner
                .decode_as_with_len(name, data)
                .map(|(msg, _)| msg)
                .map_err(to_py),
        }
    }

    fn json_options() -> SerializeOptions {
        SerializeOptions::new()
            .use_proto_field_name(true)
            .stringify_64_bit_integers(false)
    }
}

#[pymethods]
impl Codec {
    /// A codec with the built-in field codecs and no type loaded.
    #[new]
    fn new() -> Self {
        Codec {
            inner: dccl::Codec::new(),
            strict: false,
        }
    }

    /// Validates and loads the message type `name` (full name, e.g.
    /// `goby.example.NavigationReport`) from the descriptor pool.
    /// Raises `LookupError` if no such type is known, `DcclException` if it
    /// is not a valid DCCL type (the error names the message and field).
    fn load(&mut self, name: &str) -> PyResult<()> {
        let desc = pool::message(name).ok_or_else(|| {
            PyLookupError::new_err(format!(
                "message type {name} is not known: load its .proto file or import its _pb2 module"
            ))
        })?;
        self.inner.load(&desc).map_err(to_py)
    }

    /// Removes a loaded type.
    fn unload(&mut self, name: &str) {
        self.inner.unload(name);
    }

    /// Full names of the loaded types, sorted.
    fn loaded(&self) -> Vec<String> {
        self.inner.loaded()
    }

    /// DCCL id of a type by name (loaded or not: read from its `(dccl.msg)` option).
    fn id_of_name(&self, name: &str) -> PyResult<u32> {
        if let Ok(id) = self.inner.id_of(name) {
            return Ok(id);
        }
        let desc = self.descriptor(name)?;
        let options = dccl::field::message_options(&desc)
            .map_err(|e| DcclException::new_err(format!("message {name}: {e}")))?;
        match options.id {
            Some(id) if id >= 0 => Ok(id as u32),
            _ => Err(DcclException::new_err(format!(
                "message {name} has no (dccl.msg).id"
            ))),
        }
    }

    /// DCCL id at the start of encoded bytes.
    fn id_of_bytes(&self, data: &[u8]) -> PyResult<u32> {
        self.inner.read_id(data).map_err(to_py)
    }

    /// Encodes the message `name` given as protobuf wire bytes; returns the
    /// DCCL bytes and the values encoding changed, as `(field path, reason)`
    /// pairs (none in strict mode, which raises instead).
    fn encode<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        data: &[u8],
    ) -> PyResult<(Bound<'py, PyBytes>, Changes)> {
        let msg = self.parse(name, data)?;
        let (bytes, changes) = self.encode_checked(&msg)?;
        Ok((PyBytes::new(py, &bytes), changes))
    }

    /// The values encoding the message `name` (protobuf wire bytes) would
    /// change, as `(field path, reason)` pairs, strict mode or not (a
    /// `dccl.time` value the receiver would decode on another date
    /// included); adaptive
    /// arithmetic models are left as they are.
    fn check(&self, name: &str, data: &[u8]) -> PyResult<Changes> {
        let msg = self.parse(name, data)?;
        let mut changes = if self.strict {
            let mut lenient = self.inner.clone();
            lenient.set_strict(false);
            lenient.check(&msg)
        } else {
            self.inner.check(&msg)
        }
        .map_err(to_py)?;
        // A time the receiver would decode on another date.
        changes.extend(self.inner.moved_dates(&msg).map_err(to_py)?);
        Ok(pairs(changes))
    }

    /// Encodes a message given as proto3 JSON text (field names as in the
    /// `.proto` or lowerCamelCase); returns bytes and changes as `encode` does.
    fn encode_json<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        text: &str,
    ) -> PyResult<(Bound<'py, PyBytes>, Changes)> {
        let desc = self.descriptor(name)?;
        let mut de = serde_json::Deserializer::from_str(text);
        let msg =
            DynamicMessage::deserialize_with_options(desc, &mut de, &DeserializeOptions::new())
                .and_then(|m| de.end().map(|()| m))
                .map_err(|e| {
                    DcclException::new_err(format!(
                        "cannot encode (message {name}): invalid JSON: {e}"
                    ))
                })?;
        let (bytes, changes) = self.encode_checked(&msg)?;
        Ok((PyBytes::new(py, &bytes), changes))
    }

    /// Encoded size in bytes of the message `name` given as protobuf wire bytes.
    fn size(&self, name: &str, data: &[u8]) -> PyResult<usize> {
        let msg = self.parse(name, data)?;
        self.inner.size(&msg).map_err(to_py)
    }

    /// Decodes one message; returns `(full name, protobuf wire bytes)`.
    /// Bytes after the message are ignored. With `name`, the message is
    /// decoded as that loaded type (how an `omit_id` type is decoded; for
    /// another type the id read must be its id).
    #[pyo3(signature = (data, name=None))]
    fn decode<'py>(
        &self,
        py: Python<'py>,
        data: &[u8],
        name: Option<&str>,
    ) -> PyResult<(String, Bound<'py, PyBytes>)> {
        let msg = self.decode_one(data, name)?;
        Ok((
            msg.descriptor().full_name().to_string(),
            PyBytes::new(py, &msg.encode_to_vec()),
        ))
    }

    /// Decodes every message of a frame of concatenated messages; returns `[(full name, wire bytes)]`.
    fn decode_all<'py>(
        &self,
        py: Python<'py>,
        data: &[u8],
    ) -> PyResult<Vec<(String, Bound<'py, PyBytes>)>> {
        let msgs = self.inner.decode_all(data).map_err(to_py)?;
        Ok(msgs
            .iter()
            .map(|m| {
                (
                    m.descriptor().full_name().to_string(),
                    PyBytes::new(py, &m.encode_to_vec()),
                )
            })
            .collect())
    }

    /// Decodes one message to `(full name, proto3 JSON text)` (field names
    /// as in the `.proto`); `name` as for `decode`.
    #[pyo3(signature = (data, name=None))]
    fn decode_json(&self, data: &[u8], name: Option<&str>) -> PyResult<(String, String)> {
        let msg = self.decode_one(data, name)?;
        let mut out = serde_json::Serializer::new(Vec::new());
        msg.serialize_with_options(&mut out, &Self::json_options())
            .map_err(|e| {
                DcclException::new_err(format!("message {}: {e}", msg.descriptor().full_name()))
            })?;
        let text = String::from_utf8(out.into_inner()).unwrap_or_default();
        Ok((msg.descriptor().full_name().to_string(), text))
    }

    /// Decodes one message to the reference one-line text form (`x: 1 y:
    /// 2`); `name` as for `decode`.
    #[pyo3(signature = (data, name=None))]
    fn decode_text(&self, data: &[u8], name: Option<&str>) -> PyResult<(String, String)> {
        let msg = self.decode_one(data, name)?;
        Ok((
            msg.descriptor().full_name().to_string(),
            dccl::short_debug_string(&msg),
        ))
    }

    /// Largest encoded size in bytes of a loaded type.
    fn max_size(&self, name: &str) -> PyResult<usize> {
        self.inner.max_size(name).map_err(to_py)
    }

    /// Smallest encoded size in bytes of a loaded type.
    fn min_size(&self, name: &str) -> PyResult<usize> {
        self.inner.min_size(name).map_err(to_py)
    }

    /// The 64-bit message-definition hash of a loaded type (as libdccl computes it).
    fn hash(&self, name: &str) -> PyResult<u64> {
        self.inner.hash(name).map_err(to_py)
    }

    /// Field-by-field size report of a loaded type, in libdccl's `analyze` layout.
    fn analyze(&self, name: &str) -> PyResult<String> {
        self.inner.analyze(name).map_err(to_py)
    }

    /// Strict mode: out-of-range values, over-long strings and arrays raise.
    fn set_strict(&mut self, enabled: bool) {
        self.strict = enabled;
        self.inner.set_strict(enabled);
    }

    /// Encrypts message bodies (AES-256-CTR, key SHA-256 of the passphrase,
    /// the empty one included, as libdccl does), except for the DCCL ids in
    /// `skip_ids`. `None` turns encryption off.
    fn set_crypto_passphrase(&mut self, passphrase: Option<&str>, skip_ids: Vec<u32>) {
        match passphrase {
            Some(passphrase) => self
                .inner
                .set_passphrase_with_exceptions(passphrase, skip_ids),
            None => self.inner.clear_passphrase(),
        }
    }

    /// Loads arithmetic-codec models (`dccl.arith.protobuf.ArithmeticModel` in
    /// text format, one per line or concatenated); returns their names.
    fn load_arithmetic_models(&mut self, text: &str) -> PyResult<Vec<String>> {
        self.inner.load_arithmetic_models(text).map_err(to_py)
    }
}

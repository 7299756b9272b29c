//! `dccl._dccl.Codec`: the `dccl` crate's codec over serialized protobuf
//! messages. The Python package wraps it to take and return
//! `google.protobuf` message objects (`dccl/__init__.py`); every value
//! crosses the boundary as the message's protobuf wire bytes, so no logic of
//! the codec lives here.

use std::collections::HashMap;
use std::hint::black_box;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::Mutex;
use std::time::Instant;

use dccl::prost_reflect::{
    DeserializeOptions, DynamicMessage, MessageDescriptor, ReflectMessage, SerializeOptions,
};
use prost::Message;
use std::ffi::CString;

use pyo3::exceptions::{PyLookupError, PyUserWarning, PyValueError};
use pyo3::prelude::*;
use pyo3::types::{PyBytes, PyDict, PyList, PyModule, PyString, PyTuple};
use pyo3::{intern, PyTypeInfo};

use crate::errors::{to_py, DcclException, DcclOutOfRangeException};
use crate::pool;
use crate::wire::Plans;

/// Values changed by encoding, as `(field path, reason)` pairs.
type Changes = Vec<(String, String)>;

fn pairs(changes: Vec<dccl::ValueChange>) -> Changes {
    changes.into_iter().map(|c| (c.field, c.reason)).collect()
}

/// A message type as the codec encodes it: its descriptor, found once by
/// name, so that each message is encoded without a look-up of its type.
/// From `Codec.message_type(name)`.
#[pyclass(module = "dccl._dccl", name = "MessageType", frozen)]
pub struct MessageType {
    desc: MessageDescriptor,
    name: Py<PyString>,
    /// `(codec, plan)`: the wire plan the codec `codec` (its `id`) made for
    /// the type when it loaded it.
    plan: Option<(u64, usize)>,
}

#[pymethods]
impl MessageType {
    /// The full name of the type (`goby.example.NavigationReport`).
    #[getter]
    fn name(&self, py: Python<'_>) -> Py<PyString> {
        self.name.clone_ref(py)
    }
}

/// A DCCL codec: load message types by full name, then encode and decode
/// them. Messages go in and out as `(full name, protobuf wire bytes)`.
#[pyclass(module = "dccl._dccl", name = "Codec")]
pub struct Codec {
    inner: dccl::Codec,
    strict: bool,
    /// What each loaded type's messages cross with, by full name.
    loaded: HashMap<String, Loaded>,
    /// The wire plans of the loaded types.
    wire: Plans,
    /// This codec among the others of the process (for its `MessageType`s).
    id: u64,
    /// What the package lends it (see `Codec.__new__`).
    python: Option<PythonSide>,
}

/// A loaded type's full name as a Python string (handed out with every
/// message decoded rather than made again) and its wire plan.
struct Loaded {
    name: Py<PyString>,
    plan: Option<usize>,
}

thread_local! {
    /// Where decoded messages are written before they are copied into
    /// Python bytes (kept, so that writing one allocates nothing).
    static SCRATCH: std::cell::RefCell<Vec<u8>> = std::cell::RefCell::new(Vec::with_capacity(256));
}

/// Numbers the codecs of the process.
static CODECS: AtomicU64 = AtomicU64::new(0);

/// What the package's Python side lends the native codec: the dict of
/// decoded messages' classes by full name, the function making a missing
/// one, and the category of value-change warnings.
struct PythonSide {
    classes: Py<PyDict>,
    message_class: Py<PyAny>,
    warning: Py<PyAny>,
    /// The `warnings` module, whose filters say whether value-change
    /// warnings would be shown; `None` when its filters are per context
    /// (`sys.flags.context_aware_warnings`): the changes are then always made.
    warnings: Option<Py<PyModule>>,
    /// The last answer of [`Codec::changes_ignored`], with what it was
    /// computed from.
    ignored: Mutex<Option<(FiltersKey, bool)>>,
}

/// What the filters were when their answer was computed: the filter list
/// (its identity, its length, its first entry: every change the
/// `warnings` functions make moves one of these) and the default action.
type FiltersKey = (usize, usize, usize, usize);

/// The `warnings` module when its filters are global (not per context).
fn global_warning_filters(py: Python<'_>) -> Option<Py<PyModule>> {
    let per_context = py
        .import("sys")
        .and_then(|sys| sys.getattr("flags"))
        .and_then(|flags| flags.getattr("context_aware_warnings"))
        .and_then(|v| v.is_truthy())
        .unwrap_or(false);
    if per_context {
        return None;
    }
    py.import("warnings").ok().map(Bound::unbind)
}

/// Whether the filters `filters` (and the default action `default`) ignore
/// every warning of `category`: the first filter for the category (or a
/// base class of it) is `ignore` and matches any text, module and line.
/// False when that filter depends on the text, module or line.
fn filters_ignore(
    filters: &Bound<'_, PyList>,
    default: &Bound<'_, PyAny>,
    category: &Bound<'_, PyAny>,
) -> PyResult<bool> {
    let py = filters.py();
    for entry in filters.iter() {
        let entry = entry.cast_into::<PyTuple>()?;
        if entry.len() != 5 {
            return Ok(false);
        }
        let filter_category = entry.get_item(2)?;
        let applies = py
            .import("builtins")?
            .getattr("issubclass")?
            .call1((category, &filter_category))?
            .is_truthy()?;
        if !applies {
            continue;
        }
        let any_text = entry.get_item(1)?.is_none() && entry.get_item(3)?.is_none();
        let any_line = entry
            .get_item(4)?
            .extract::<i64>()
            .map(|l| l == 0)
            .unwrap_or(false);
        return Ok(any_text && any_line && entry.get_item(0)?.extract::<String>()? == "ignore");
    }
    Ok(default
        .extract::<String>()
        .map(|d| d == "ignore")
        .unwrap_or(false))
}

/// Emits one `DcclValueChangedWarning` per change, attributed to the
/// caller of the package's method (two Python frames up: the package's
/// method, its caller); an error when a filter turns them into errors.
fn warn_changes(
    py: Python<'_>,
    side: Option<&PythonSide>,
    changes: &[dccl::ValueChange],
) -> PyResult<()> {
    if changes.is_empty() {
        return Ok(());
    }
    let category = match side {
        Some(side) => side.warning.bind(py).clone(),
        None => PyUserWarning::type_object(py).into_any(),
    };
    for change in changes {
        let text = CString::new(change.to_string().replace('\0', "\\0"))
            .map_err(|e| PyValueError::new_err(e.to_string()))?;
        PyErr::warn(py, &category, &text, 2)?;
    }
    Ok(())
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

    /// Whether value-change warnings would all be ignored (the filters the
    /// `warnings` module holds now ignore `DcclValueChangedWarning`
    /// whatever the text, module and line): the changes then need not be
    /// made. The answer is kept until the filter list, its length, its
    /// first entry or the default action change.
    fn changes_ignored(&self, py: Python<'_>) -> bool {
        let Some(side) = &self.python else {
            return false;
        };
        let Some(warnings) = &side.warnings else {
            return false;
        };
        let warnings = warnings.bind(py);
        let (Ok(filters), Ok(default)) = (
            warnings.getattr(intern!(py, "filters")),
            warnings.getattr(intern!(py, "defaultaction")),
        ) else {
            return false;
        };
        let Ok(filters) = filters.cast_into::<PyList>() else {
            return false;
        };
        let first = filters
            .get_item(0)
            .map(|f| f.as_ptr() as usize)
            .unwrap_or(0);
        let key = (
            filters.as_ptr() as usize,
            filters.len(),
            first,
            default.as_ptr() as usize,
        );
        let mut cached = side.ignored.lock().unwrap_or_else(|e| e.into_inner());
        if let Some((k, ignored)) = *cached {
            if k == key {
                return ignored;
            }
        }
        let ignored = filters_ignore(&filters, &default, side.warning.bind(py)).unwrap_or(false);
        *cached = Some((key, ignored));
        ignored
    }

    /// Encodes, reporting the values the codec changed (none when the
    /// warnings about them would be ignored: see `changes_ignored`); in
    /// strict mode an error that the lenient codec would not raise is a
    /// value out of its bounds: `DcclOutOfRangeException`.
    fn encode_checked(
        &self,
        py: Python<'_>,
        msg: &DynamicMessage,
    ) -> PyResult<(Vec<u8>, Vec<dccl::ValueChange>)> {
        let encoded = if self.changes_ignored(py) {
            self.inner.encode(msg).map(|bytes| (bytes, Vec::new()))
        } else {
            let mut bytes = Vec::new();
            self.inner
                .encode_with(msg, &mut bytes, &dccl::EncodeOptions::with_changes())
                .and_then(|encoded| {
                    let mut changes = encoded.changes;
                    changes.extend(self.inner.moved_dates(msg)?);
                    Ok((bytes, changes))
                })
        };
        encoded.map_err(|e| self.strict_error(e, |lenient| lenient.encode(msg).map(drop)))
    }

    /// The exception of an encoding error: in strict mode, an error that
    /// the lenient codec (`lenient_ok` tries it) would not raise is a value
    /// out of its bounds, `DcclOutOfRangeException`; else `DcclException`.
    fn strict_error(
        &self,
        e: dccl::Error,
        lenient_ok: impl FnOnce(&dccl::Codec) -> dccl::Result<()>,
    ) -> PyErr {
        if self.strict && matches!(e, dccl::Error::Encode { .. }) {
            let mut lenient = self.inner.clone();
            lenient.set_strict(false);
            if lenient_ok(&lenient).is_ok() {
                return DcclOutOfRangeException::new_err(e.to_string());
            }
        }
        to_py(e)
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
                .decode_with(data, &dccl::DecodeOptions::as_type(name))
                .map(|d| d.message)
                .map_err(to_py),
        }
    }

    /// `(full name, protobuf wire bytes)` of a decoded message, the name
    /// the one made when its type was loaded.
    fn decoded<'py>(&self, py: Python<'py>, msg: &DynamicMessage) -> PyResult<Bound<'py, PyTuple>> {
        let (name, wire) = self.decoded_parts(py, msg);
        PyTuple::new(py, [name.into_any(), wire.into_any()])
    }

    /// The full name and protobuf wire bytes of a decoded message.
    fn decoded_parts<'py>(
        &self,
        py: Python<'py>,
        msg: &DynamicMessage,
    ) -> (Bound<'py, PyString>, Bound<'py, PyBytes>) {
        let desc = msg.descriptor();
        let loaded = self.loaded.get(desc.full_name());
        let name = match loaded {
            Some(l) => l.name.clone_ref(py).into_bound(py),
            None => PyString::new(py, desc.full_name()),
        };
        let wire = match loaded.and_then(|l| l.plan) {
            Some(plan) => SCRATCH.with_borrow_mut(|out| {
                out.clear();
                self.wire.encode(plan, msg, out);
                PyBytes::new(py, out)
            }),
            None => PyBytes::new(py, &msg.encode_to_vec()),
        };
        (name, wire)
    }

    /// The message of `message_type` encoded in `data` (protobuf wire bytes).
    fn parse_typed(&self, t: &MessageType, data: &[u8]) -> PyResult<DynamicMessage> {
        DynamicMessage::decode(t.desc.clone(), data).map_err(|e| {
            DcclException::new_err(format!(
                "cannot encode (message {}): not a valid protobuf message of that type: {e}",
                t.desc.full_name()
            ))
        })
    }

    fn json_options() -> SerializeOptions {
        SerializeOptions::new()
            .use_proto_field_name(true)
            .stringify_64_bit_integers(false)
    }
}

#[pymethods]
impl Codec {
    /// A codec with the built-in field codecs and no type loaded. The
    /// package passes `classes` (full name -> the class decoded messages
    /// get), `message_class` (makes the class of a type missing from
    /// `classes`) and `warning` (the category of value-change warnings;
    /// `UserWarning` without it); `decode_message` needs the first two.
    #[new]
    #[pyo3(signature = (classes=None, message_class=None, warning=None))]
    fn new(
        py: Python<'_>,
        classes: Option<Bound<'_, PyDict>>,
        message_class: Option<Bound<'_, PyAny>>,
        warning: Option<Bound<'_, PyAny>>,
    ) -> Self {
        let python = match (classes, message_class) {
            (Some(classes), Some(message_class)) => Some(PythonSide {
                classes: classes.unbind(),
                message_class: message_class.unbind(),
                warning: match warning {
                    Some(w) => w.unbind(),
                    None => PyUserWarning::type_object(py).into_any().unbind(),
                },
                warnings: global_warning_filters(py),
                ignored: Mutex::new(None),
            }),
            _ => None,
        };
        Codec {
            python,
            inner: dccl::Codec::new(),
            strict: false,
            loaded: HashMap::new(),
            wire: Plans::default(),
            id: CODECS.fetch_add(1, Ordering::Relaxed),
        }
    }

    /// Validates and loads the message type `name` (full name, e.g.
    /// `goby.example.NavigationReport`) from the descriptor pool.
    /// Raises `LookupError` if no such type is known, `DcclException` if it
    /// is not a valid DCCL type (the error names the message and field).
    fn load(&mut self, py: Python<'_>, name: &str) -> PyResult<()> {
        let desc = pool::message(name).ok_or_else(|| {
            PyLookupError::new_err(format!(
                "message type {name} is not known: load its .proto file or import its _pb2 module"
            ))
        })?;
        self.inner.load(&desc).map_err(to_py)?;
        let plan = self.wire.plan(&desc);
        self.loaded.insert(
            name.to_string(),
            Loaded {
                name: PyString::new(py, name).unbind(),
                plan,
            },
        );
        Ok(())
    }

    /// Removes a loaded type.
    fn unload(&mut self, name: &str) {
        self.inner.unload(name);
        self.loaded.remove(name);
    }

    /// The type `name` (full name) as `encode` takes it: the descriptor this
    /// codec loaded, else the pool's. Raises `DcclException` for an unknown name.
    fn message_type(&self, py: Python<'_>, name: &str) -> PyResult<MessageType> {
        Ok(MessageType {
            desc: self.descriptor(name)?,
            name: PyString::new(py, name).unbind(),
            plan: self
                .loaded
                .get(name)
                .and_then(|l| l.plan)
                .map(|p| (self.id, p)),
        })
    }

    /// Checks the package's protobuf paths against prost-reflect on one
    /// message of `message_type` (protobuf wire bytes): encoding the bytes
    /// as they are gives what decoding them with prost-reflect and
    /// encoding that message gives (bytes and changes, or the same error),
    /// and writing the decoded message gives prost-reflect's bytes. Raises
    /// `DcclException` saying what differs; a test of the package, not for use.
    fn check_wire(&self, message_type: &Bound<'_, MessageType>, data: &[u8]) -> PyResult<()> {
        let t = message_type.get();
        let name = t.desc.full_name();
        let Some((_, plan)) = t.plan.filter(|(codec, _)| *codec == self.id) else {
            return Err(DcclException::new_err(format!(
                "{name}: no wire plan in this codec"
            )));
        };
        let show = |r: dccl::Result<(Vec<u8>, Vec<dccl::ValueChange>)>| match r {
            Ok((bytes, changes)) => format!("{bytes:02x?} {changes:?}"),
            Err(e) => format!("error: {e}"),
        };
        let reference = DynamicMessage::decode(t.desc.clone(), data);
        let with_changes = |msg: &dyn Fn(&mut Vec<u8>) -> dccl::Result<dccl::Encoded>| {
            let mut bytes = Vec::new();
            msg(&mut bytes).map(|e| (bytes, e.changes))
        };
        let changes = dccl::EncodeOptions::with_changes();
        let direct = show(with_changes(&|out| {
            self.inner
                .encode_with(&dccl::Protobuf::new(name, data), out, &changes)
        }));
        let through = show(match &reference {
            Ok(m) => with_changes(&|out| self.inner.encode_with(m, out, &changes)),
            Err(e) => Err(dccl::Error::Encode {
                location: dccl::Location {
                    message: name.to_string(),
                    field: String::new(),
                },
                reason: format!("not a valid protobuf message of that type: {e}"),
            }),
        });
        if direct != through {
            return Err(DcclException::new_err(format!(
                "{name}: encoding the bytes gives {direct}, through prost-reflect {through}"
            )));
        }
        // Written are messages the codec decoded: without unknown fields.
        if let Some(reference) = reference
            .ok()
            .filter(|m| m.unknown_fields().next().is_none())
        {
            let mut out = Vec::new();
            self.wire.encode(plan, &reference, &mut out);
            if out != reference.encode_to_vec() {
                return Err(DcclException::new_err(format!(
                    "{name}: the plan writes {out:02x?}, prost-reflect {:02x?}",
                    reference.encode_to_vec()
                )));
            }
        }
        Ok(())
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

    /// Encodes a message of the type `message_type` (from `message_type`)
    /// given as protobuf wire bytes; returns the DCCL bytes. Each value
    /// encoding changed is a `DcclValueChangedWarning` attributed to the
    /// caller of the package's method (strict mode raises instead).
    fn encode<'py>(
        &self,
        py: Python<'py>,
        message_type: &Bound<'py, MessageType>,
        data: &[u8],
    ) -> PyResult<Bound<'py, PyBytes>> {
        let t = message_type.get();
        let name = t.desc.full_name();
        let ignored = self.changes_ignored(py);
        let (bytes, changes) = if ignored || !self.inner.restores_dates(name).unwrap_or(true) {
            // The protobuf bytes encoded as they are (no dynamic message),
            // unless dates the receiver would move are to be told.
            let protobuf = dccl::Protobuf::new(name, data);
            let options = dccl::EncodeOptions { changes: !ignored };
            let mut out = Vec::with_capacity(64);
            let encoded = self.inner.encode_with(&protobuf, &mut out, &options);
            encoded
                .map(|e| (out, e.changes))
                .map_err(|e| self.strict_error(e, |lenient| lenient.encode(&protobuf).map(drop)))?
        } else {
            let msg = self.parse_typed(t, data)?;
            self.encode_checked(py, &msg)?
        };
        let bytes = PyBytes::new(py, &bytes);
        warn_changes(py, self.python.as_ref(), &changes)?;
        Ok(bytes)
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
    /// `.proto` or lowerCamelCase); returns the bytes, warning as `encode` does.
    fn encode_json<'py>(
        &self,
        py: Python<'py>,
        name: &str,
        text: &str,
    ) -> PyResult<Bound<'py, PyBytes>> {
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
        let (bytes, changes) = self.encode_checked(py, &msg)?;
        let bytes = PyBytes::new(py, &bytes);
        warn_changes(py, self.python.as_ref(), &changes)?;
        Ok(bytes)
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
    ) -> PyResult<Bound<'py, PyTuple>> {
        let msg = self.decode_one(data, name)?;
        self.decoded(py, &msg)
    }

    /// Decodes one message (its type found by its id) to a `google.protobuf`
    /// message: of the class the package's `classes` dict holds for its
    /// type, else the one `message_class` makes (see `Codec.__new__`).
    fn decode_message<'py>(&self, py: Python<'py>, data: &[u8]) -> PyResult<Bound<'py, PyAny>> {
        let msg = self.decode_one(data, None)?;
        let side = self.python.as_ref().ok_or_else(|| {
            PyValueError::new_err(
                "decode_message: the codec was made without the package's classes",
            )
        })?;
        let (name, wire) = self.decoded_parts(py, &msg);
        drop(msg);
        let class = match side.classes.bind(py).get_item(&name)? {
            Some(class) => class,
            None => side.message_class.bind(py).call1((&name,))?,
        };
        class.call_method1(intern!(py, "FromString"), (wire,))
    }

    /// Decodes every message of a frame of concatenated messages; returns `[(full name, wire bytes)]`.
    fn decode_all<'py>(&self, py: Python<'py>, data: &[u8]) -> PyResult<Vec<Bound<'py, PyTuple>>> {
        let msgs = self.inner.decode_all(data).map_err(to_py)?;
        msgs.iter().map(|m| self.decoded(py, m)).collect()
    }

    /// The Rust library alone on the same messages, for the package's
    /// benchmark (`python/benches/bench.py`): microseconds per message of
    /// the fastest of `rounds` passes, `(encode, decode)`, encoding each
    /// message of `types` given as protobuf wire bytes (parsed before the
    /// clock starts) and decoding each of `encoded`.
    fn time_native(
        &self,
        types: Vec<Bound<'_, MessageType>>,
        wires: Vec<Vec<u8>>,
        encoded: Vec<Vec<u8>>,
        rounds: usize,
    ) -> PyResult<(f64, f64)> {
        if types.len() != wires.len() || wires.is_empty() || encoded.is_empty() || rounds == 0 {
            return Err(PyValueError::new_err(
                "time_native: as many types as messages, some messages, some rounds",
            ));
        }
        let messages = types
            .iter()
            .zip(&wires)
            .map(|(t, w)| self.parse_typed(t.get(), w))
            .collect::<PyResult<Vec<_>>>()?;
        let mut out = Vec::with_capacity(256);
        let (mut encode, mut decode) = (f64::INFINITY, f64::INFINITY);
        for _ in 0..rounds {
            let start = Instant::now();
            for m in &messages {
                out.clear();
                self.inner
                    .encode_with(black_box(m), &mut out, &dccl::EncodeOptions::default())
                    .map_err(to_py)?;
                black_box(&out);
            }
            encode = encode.min(start.elapsed().as_secs_f64() / messages.len() as f64);
            let start = Instant::now();
            for bytes in &encoded {
                black_box(self.inner.decode(black_box(bytes)).map_err(to_py)?);
            }
            decode = decode.min(start.elapsed().as_secs_f64() / encoded.len() as f64);
        }
        Ok((encode * 1e6, decode * 1e6))
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

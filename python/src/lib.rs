//! The native part of the `dccl` Python package (`dccl._dccl`): the `dccl`
//! crate's codec and a process-wide descriptor pool, exchanging messages as
//! protobuf wire bytes. The Python side (`dccl/__init__.py`) turns them into
//! `google.protobuf` message objects.

mod codec;
mod errors;
mod pool;
mod wire;

use std::path::PathBuf;

use pyo3::prelude::*;
use pyo3::types::PyBytes;

use errors::{to_py, DcclException, DcclOutOfRangeException};

/// Adds a directory searched for the imports of `.proto` files loaded
/// later; raises `DcclException` when it is not a directory.
#[pyfunction]
fn add_include_path(dir: PathBuf) -> PyResult<()> {
    pool::add_include_path(dir).map_err(to_py)
}

/// Compiles a `.proto` file (no `protoc`) into the pool; returns the full
/// names of the message types it defines.
#[pyfunction]
fn load_proto_file(path: PathBuf) -> PyResult<Vec<String>> {
    pool::load_proto_file(path).map_err(to_py)
}

/// Adds a serialized `FileDescriptorProto` (a `_pb2` module's
/// `DESCRIPTOR.serialized_pb`); its imports must be in the pool already.
/// Returns whether it was new.
#[pyfunction]
fn add_serialized_file(data: &[u8]) -> PyResult<bool> {
    pool::add_serialized_file(data).map_err(to_py)
}

/// Whether a file of that name (e.g. `dccl/option_extensions.proto`) is in the pool.
#[pyfunction]
fn has_file(name: &str) -> bool {
    pool::has_file(name)
}

/// Whether a message type of that full name is in the pool.
#[pyfunction]
fn has_message(name: &str) -> bool {
    pool::message(name).is_some()
}

/// Serialized `FileDescriptorProto` of a file of the pool (custom options kept).
#[pyfunction]
fn file_descriptor<'py>(py: Python<'py>, name: &str) -> PyResult<Bound<'py, PyBytes>> {
    pool::file_bytes(name)
        .map(|b| PyBytes::new(py, &b))
        .ok_or_else(|| {
            DcclException::new_err(format!("{name}: no such file in the descriptor pool"))
        })
}

/// `[(file name, serialized FileDescriptorProto)]` of the file defining the
/// message type `name` and of all its imports, imports first.
#[pyfunction]
fn files_for_message<'py>(
    py: Python<'py>,
    name: &str,
) -> PyResult<Vec<(String, Bound<'py, PyBytes>)>> {
    let desc =
        pool::message(name).ok_or_else(|| to_py(dccl::Error::UnknownType(name.to_string())))?;
    Ok(pool::files_for(&desc)
        .into_iter()
        .map(|(n, b)| (n, PyBytes::new(py, &b)))
        .collect())
}

/// The native module `dccl._dccl`.
#[pymodule]
fn _dccl(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add_class::<codec::Codec>()?;
    m.add_class::<codec::MessageType>()?;
    m.add("DcclException", py.get_type::<DcclException>())?;
    m.add(
        "DcclOutOfRangeException",
        py.get_type::<DcclOutOfRangeException>(),
    )?;
    m.add("EMBEDDED_FILES", pool::EMBEDDED_FILES.to_vec())?;
    m.add_function(wrap_pyfunction!(add_include_path, m)?)?;
    m.add_function(wrap_pyfunction!(load_proto_file, m)?)?;
    m.add_function(wrap_pyfunction!(add_serialized_file, m)?)?;
    m.add_function(wrap_pyfunction!(has_file, m)?)?;
    m.add_function(wrap_pyfunction!(has_message, m)?)?;
    m.add_function(wrap_pyfunction!(file_descriptor, m)?)?;
    m.add_function(wrap_pyfunction!(files_for_message, m)?)?;
    Ok(())
}

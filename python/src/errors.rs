//! The exceptions of the `dccl` package and the mapping of the library's errors onto them.

use pyo3::create_exception;
use pyo3::exceptions::PyException;
use pyo3::PyErr;

create_exception!(
    dccl,
    DcclException,
    PyException,
    "An error of DCCL: an invalid definition, a value that cannot be encoded, bytes that cannot \
     be decoded. The message names the message type and, where it applies, the field."
);

create_exception!(
    dccl,
    DcclOutOfRangeException,
    DcclException,
    "In strict mode: a value outside its (dccl.field) bounds, a string or bytes over max_length, \
     a repeated field over max_repeat. The message names the message type and the field."
);

/// The library's error as a `DcclException`, its text naming message and field.
pub fn to_py(e: dccl::Error) -> PyErr {
    DcclException::new_err(e.to_string())
}

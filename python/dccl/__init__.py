"""DCCL, the Dynamic Compact Control Language, for Python.

Packs protobuf messages into the fewest bits their ``(dccl.field)`` bounds
allow, byte for byte as the reference C++ library libdccl 4 does, for links
that carry a few dozen bytes at a time (acoustic modems, satellite, radio).
The codec is the Rust ``dccl`` crate; nothing needs a C++ toolchain or
``protoc``.

The API is that of the reference binding, so its scripts run unchanged::

    import dccl, navreport_pb2
    dccl.loadProtoFile("/abs/path/navreport.proto")   # or just import the _pb2
    codec = dccl.Codec()
    codec.load("NavigationReport")
    data = codec.encode(navreport_pb2.NavigationReport(x=450, y=550))
    print(codec.decode(data))

Message types come from ``.proto`` files compiled at run time
(:func:`loadProtoFile`) or from generated ``_pb2`` modules (their file
descriptors carry the DCCL options); both go through the same codec.
Messages go in and out as ``google.protobuf`` message objects: the user's
generated class when one is imported, else a class built from the descriptor.

Beyond the reference binding: :meth:`Codec.decode_all` for frames of several
messages, :meth:`Codec.analyze`, :meth:`Codec.hash`, :meth:`Codec.max_size`,
proto3-JSON and ``dict`` in and out, and :func:`message_class`.

Errors raise :class:`DcclException` (strict-mode range errors its subclass
:class:`DcclOutOfRangeException`); the text names the message type and the
field. Outside strict mode, each value that encoding changes (an
out-of-range number sent as not present, a string or array truncated ...)
emits a :class:`DcclValueChangedWarning`; :meth:`Codec.check` lists them
without encoding.
"""

import json as _json
import os as _os

from google.protobuf import descriptor_pool as _descriptor_pool
from google.protobuf import message as _message
from google.protobuf import message_factory as _message_factory

from . import _dccl
from ._dccl import DcclException, DcclOutOfRangeException

try:
    from importlib.metadata import version as _version

    __version__ = _version("dccl")
except Exception:  # pragma: no cover - running from a source tree
    __version__ = "0"

__all__ = [
    "Codec",
    "DcclException",
    "DcclOutOfRangeException",
    "DcclValueChangedWarning",
    "addProtoIncludePath",
    "loadProtoFile",
    "add_proto_include_path",
    "load_proto_file",
    "register",
    "message_class",
    "proto_include",
]



class DcclValueChangedWarning(UserWarning):
    """Outside strict mode, a value that encoding changed: a number outside
    its ``(dccl.field)`` bounds sent as not present, NaN sent as the minimum,
    a string, bytes or repeated field cut to its maximum, an undefined enum
    value dropped. One warning per value; the text names the message type,
    the field path and what was done (``message apitest.Ping, field range:
    9999 is out of range [0, 5000]: sent as not present``). Silence them with
    ``warnings.simplefilter("ignore", dccl.DcclValueChangedWarning)``, or
    turn them into errors with ``"error"``; :meth:`Codec.check` lists them
    without encoding, and :meth:`Codec.set_strict` raises instead."""


# The id codec of libdccl 4 (the only one): one byte for ids 0-127, two for 128-32767.
DEFAULT_ID_CODEC = "dccl.default.id"


def proto_include():
    """The directory of the DCCL option ``.proto`` files this package ships,
    for ``protoc -I`` when generating ``_pb2`` modules of one's own messages
    (as ``grpc_tools`` gives its own includes): ``dccl/option_extensions.proto``,
    the arithmetic codec's ``dccl/arithmetic/protobuf/*.proto`` and
    ``goby/dccl/delta_extensions.proto``. E.g.::

        python -m grpc_tools.protoc -I. -I"$(python -c 'import dccl; print(dccl.proto_include())')" \
            --python_out=. my_messages.proto

    Returns an absolute path (str)."""
    return _os.path.join(_os.path.dirname(_os.path.abspath(__file__)), "include")


def addProtoIncludePath(path):
    """Adds a directory searched for the ``import`` s of ``.proto`` files
    loaded afterwards. ``path``: str or path-like. Raises
    :class:`DcclException` when it is not a directory."""
    _dccl.add_include_path(_os.fspath(path))


def loadProtoFile(path):
    """Compiles the ``.proto`` file ``path`` (str or path-like; absolute or
    relative) and its imports at run time, with no ``protoc``, and makes its
    message types known to every :class:`Codec`. Imports are searched in the
    include paths, the file's directory, then among the DCCL option files
    shipped in the package (``dccl/option_extensions.proto`` ...).

    Returns the full names of the message types the file defines (the
    reference binding returns None). Raises :class:`DcclException` naming
    file, line and column when the file does not compile. A type has one
    definition per process: loading the same file again, or another file
    defining the same types identically, is fine; a file that defines an
    already loaded type differently raises :class:`DcclException` naming the
    type, and nothing of it is loaded."""
    return _dccl.load_proto_file(_os.fspath(path))


add_proto_include_path = addProtoIncludePath
load_proto_file = loadProtoFile

# Files of the Python descriptor pools already given to the native pool.
_registered_files = set()
# Full names of message types the native pool knows.
_known_types = set()
# Full name -> the message class decoded messages get.
_classes = {}
# Message class -> full name, for the classes seen in encode, size and load.
_names = {}
# Classes for types that only the native pool knows (from loadProtoFile).
_own_pool = None


def _register_file(file_descriptor):
    name = file_descriptor.name
    if name in _registered_files:
        return
    for dependency in file_descriptor.dependencies:
        _register_file(dependency)
    if not _dccl.has_file(name):
        _dccl.add_serialized_file(file_descriptor.serialized_pb)
    _registered_files.add(name)


def register(obj):
    """Makes the message types of a generated ``_pb2`` module known to the
    codecs (this happens on its own the first time a message of the module is
    loaded by class or encoded). ``obj``: a ``_pb2`` module, a message class
    or instance, or a protobuf ``Descriptor`` / ``FileDescriptor``.
    Returns the file's name."""
    descriptor = getattr(obj, "DESCRIPTOR", obj)
    file_descriptor = getattr(descriptor, "file", descriptor)
    if not hasattr(file_descriptor, "serialized_pb"):
        raise TypeError(
            "expected a _pb2 module, a protobuf message or class, or a descriptor, got %r" % (obj,)
        )
    _register_file(file_descriptor)
    return file_descriptor.name


def _class_name(cls):
    """Full type name of the message class ``cls``; its file is made known
    to the native pool, and decoded messages of the type get this class."""
    name = _names.get(cls)
    if name is None:
        descriptor = getattr(cls, "DESCRIPTOR", None)
        name = getattr(descriptor, "full_name", None)
        if not isinstance(name, str) or not hasattr(descriptor, "file"):
            raise TypeError("expected a protobuf message, got an instance of %r" % (cls,))
        _register_file(descriptor.file)
        _known_types.add(name)
        _names[cls] = name
        _classes[name] = cls
    return name


def _type_name(obj):
    """Full type name of ``obj`` (a name, message, class or descriptor),
    making its file known to the native pool when it comes from Python."""
    if isinstance(obj, str):
        if obj not in _known_types and not _dccl.has_message(obj):
            # A type of an imported _pb2 module, named by its full name.
            try:
                descriptor = _descriptor_pool.Default().FindMessageTypeByName(obj)
            except KeyError:
                return obj
            _register_file(descriptor.file)
        _known_types.add(obj)
        return obj
    if isinstance(obj, type):
        return _class_name(obj)
    if isinstance(obj, _message.Message):
        return _class_name(type(obj))
    name = getattr(obj, "full_name", None)
    if not isinstance(name, str) or not hasattr(obj, "file"):
        raise TypeError(
            "expected a message type name, a protobuf message or class, or a Descriptor, got %r"
            % (obj,)
        )
    if name not in _known_types:
        _register_file(obj.file)
        _known_types.add(name)
    return name


def message_class(name):
    """The ``google.protobuf`` message class that decoded messages of the
    full type name ``name`` get: the last generated class passed to a codec
    (by :meth:`Codec.load`, :meth:`Codec.encode` ...) or, the first time, the
    generated class of an imported ``_pb2`` module; else a class built from
    the descriptor the native pool holds (types from :func:`loadProtoFile`).
    Raises ``KeyError`` for an unknown type."""
    global _own_pool
    cls = _classes.get(name)
    if cls is not None:
        return cls
    try:
        descriptor = _descriptor_pool.Default().FindMessageTypeByName(name)
    except KeyError:
        descriptor = None
    if descriptor is not None:
        cls = _message_factory.GetMessageClass(descriptor)
    else:
        if not _dccl.has_message(name):
            raise KeyError(
                "message type %s is not known: load its .proto file or import its _pb2 module" % name
            )
        if _own_pool is None:
            _own_pool = _descriptor_pool.DescriptorPool()
        for file_name, data in _dccl.files_for_message(name):
            try:
                _own_pool.FindFileByName(file_name)
            except KeyError:
                _own_pool.AddSerializedFile(data)
        cls = _message_factory.GetMessageClass(_own_pool.FindMessageTypeByName(name))
    _classes[name] = cls
    return cls


def _as_bytes(data):
    if isinstance(data, bytes):
        return data
    if isinstance(data, str):
        return data.encode("utf-8")
    return bytes(data)


def _optional_type_name(obj):
    return None if obj is None else _type_name(obj)


def _header_or_type(header_only, type_name):
    """``decode``'s second argument is the reference binding's
    ``header_only`` (a bool); a type given there instead (a name, class,
    message or ``Descriptor``) is the type to decode as."""
    if isinstance(header_only, (bool, int)) or header_only is None:
        return bool(header_only), type_name
    if type_name is not None:
        raise TypeError("decode() got the type twice: %r and type_name=%r" % (header_only, type_name))
    return False, header_only


def _to_message(name, wire):
    cls = _classes.get(name) or message_class(name)
    return cls.FromString(wire)


class Codec:
    """The DCCL encoder/decoder.

    ``Codec(id_codec=None, library_path=None)``: ``id_codec`` may only be the
    default ``"dccl.default.id"``; codec libraries (``library_path``) are a
    C++ feature and raise :class:`DcclException`.

    Load each message type once (:meth:`load`), then :meth:`encode` and
    :meth:`decode`. A codec is not shared between threads without a lock
    (adaptive arithmetic models change as they encode).
    """

    def __init__(self, id_codec=None, library_path=None):
        if id_codec not in (None, "", DEFAULT_ID_CODEC):
            raise DcclException("id codec %r is not available: only %s is" % (id_codec, DEFAULT_ID_CODEC))
        if library_path:
            raise DcclException(
                "cannot load codec library %s: codecs are built into this package" % library_path
            )
        # The native codec decodes straight to the classes of ``_classes``
        # (made by ``message_class`` when missing) and warns about changed
        # values with ``DcclValueChangedWarning``.
        self._codec = _dccl.Codec(_classes, message_class, DcclValueChangedWarning)
        # Generated class -> the native type handle encode takes (made once
        # per class, as the class's full name is).
        self._types = {}

    def load(self, type_name):
        """Validates and loads a message type for encoding and decoding.

        ``type_name``: full name (``"goby.example.NavigationReport"``), or a
        generated message class, message or ``Descriptor``. Raises
        ``LookupError`` for an unknown name, :class:`DcclException` (naming
        message and field) for an invalid DCCL definition."""
        self._codec.load(_type_name(type_name))
        self._types.clear()

    def unload(self, type_name):
        """Removes a loaded type."""
        self._codec.unload(_type_name(type_name))
        self._types.clear()

    def _message_type(self, cls):
        """The native handle of the generated class ``cls``'s type."""
        handle = self._types.get(cls)
        if handle is None:
            handle = self._codec.message_type(_class_name(cls))
            self._types[cls] = handle
        return handle

    def loaded(self):
        """Full names of the loaded types, sorted (list of str)."""
        return self._codec.loaded()

    def id(self, obj):
        """The DCCL id (int) of a type (``obj``: its full name as a str,
        class, message or ``Descriptor``) or of encoded bytes (``bytes``,
        ``bytearray`` or ``memoryview``: read from their first one or two
        bytes). A str is always a type name: an unknown one raises
        :class:`DcclException`."""
        if isinstance(obj, (bytes, bytearray, memoryview)):
            return self._codec.id_of_bytes(bytes(obj))
        return self._codec.id_of_name(_type_name(obj))

    def size(self, message):
        """Encoded size in bytes (int) of ``message`` (a protobuf message of a loaded type)."""
        return self._codec.size(_class_name(type(message)), message.SerializePartialToString())

    def encode(self, message, header_only=False):
        """Encodes ``message`` (a protobuf message of a loaded type); returns
        bytes (header and body, encrypted when a passphrase is set).

        Values outside their bounds are dropped or clamped as libdccl does,
        each with a :class:`DcclValueChangedWarning`, or raise
        :class:`DcclOutOfRangeException` in strict mode; a missing required
        field raises :class:`DcclException`. ``header_only`` is not
        supported (raises)."""
        if header_only:
            raise DcclException("encode(header_only=True) is not supported")
        handle = self._types.get(type(message))
        if handle is None:
            handle = self._message_type(type(message))
        # Warnings about changed values come from the native side,
        # attributed to this method's caller.
        return self._codec.encode(handle, message.SerializePartialToString())

    def check(self, message):
        """The values encoding ``message`` (a protobuf message of a loaded
        type) would change, without encoding it: a list of ``(field,
        reason)`` str pairs, ``field`` the path from the message
        (``waypoint.x``, ``hops[3]``), empty when nothing would change.
        Reports the same in strict mode (where encoding raises at the first);
        adaptive arithmetic models are left as they are."""
        return [
            (field, reason)
            for field, reason in self._codec.check(
                _class_name(type(message)), message.SerializePartialToString()
            )
        ]

    def decode(self, data, header_only=False, type_name=None):
        """Decodes one message from ``data`` (bytes; extra bytes after the
        message are ignored); the type is found by its DCCL id, or given:
        ``decode(data, "pkg.Type")``, ``decode(data, MyType)`` or
        ``type_name=`` (a full name, generated class, message or
        ``Descriptor`` of a loaded type). A type with ``omit_id: true`` sends
        no id and is decoded this way only; for another type the id read
        must be the type's. Returns a protobuf message: the generated class
        when imported, else one built from the descriptor. ``header_only``
        (the reference binding's second argument, a bool) is not supported
        (raises)."""
        if header_only is False and type_name is None and type(data) is bytes:
            # The common case, in one native call (class look-up included).
            return self._codec.decode_message(data)
        header_only, type_name = _header_or_type(header_only, type_name)
        if header_only:
            raise DcclException("decode(header_only=True) is not supported")
        name, wire = self._codec.decode(_as_bytes(data), _optional_type_name(type_name))
        return _to_message(name, wire)

    def decode_all(self, frame):
        """Decodes every message of ``frame`` (bytes: messages encoded one
        after the other); returns a list of protobuf messages."""
        return [_to_message(name, wire) for name, wire in self._codec.decode_all(_as_bytes(frame))]

    def encode_json(self, type_name, text):
        """Encodes a message of type ``type_name`` given as proto3 JSON text
        (field names as in the ``.proto`` or lowerCamelCase, enums by name,
        bytes base64); returns bytes. Changed values warn as in :meth:`encode`."""
        return self._codec.encode_json(_type_name(type_name), text)

    def encode_dict(self, type_name, values):
        """Encodes a message of type ``type_name`` given as a dict in the
        proto3-JSON shape (``{"x": 450.0, "veh_class": "AUV"}``); returns bytes.
        Changed values warn as in :meth:`encode`."""
        return self._codec.encode_json(_type_name(type_name), _json.dumps(values))

    def decode_json(self, data, with_name=False, type_name=None):
        """Decodes one message to proto3 JSON text (field names as in the
        ``.proto``, 64-bit integers as numbers). With ``with_name``, returns
        ``(full type name, text)``; ``type_name`` as for :meth:`decode`."""
        name, text = self._codec.decode_json(_as_bytes(data), _optional_type_name(type_name))
        return (name, text) if with_name else text

    def decode_dict(self, data, with_name=False, type_name=None):
        """Decodes one message to a dict in the proto3-JSON shape. With
        ``with_name``, returns ``(full type name, dict)``; ``type_name`` as
        for :meth:`decode`."""
        name, text = self._codec.decode_json(_as_bytes(data), _optional_type_name(type_name))
        values = _json.loads(text)
        return (name, values) if with_name else values

    def decode_text(self, data, type_name=None):
        """Decodes one message to libdccl's one-line text form (``x: 450
        y: 550``); ``type_name`` as for :meth:`decode`."""
        return self._codec.decode_text(_as_bytes(data), _optional_type_name(type_name))[1]

    def max_size(self, type_name):
        """Largest encoded size in bytes (int) of a loaded type."""
        return self._codec.max_size(_type_name(type_name))

    def min_size(self, type_name):
        """Smallest encoded size in bytes (int) of a loaded type."""
        return self._codec.min_size(_type_name(type_name))

    def hash(self, type_name):
        """The 64-bit message-definition hash (int) of a loaded type, as
        libdccl computes it (``"0x%016x" % h`` is the form its analyze prints).
        Two nodes whose hashes differ do not read each other's messages."""
        return self._codec.hash(_type_name(type_name))

    def analyze(self, type_name):
        """Field-by-field sizes in bits of a loaded type (str), in the layout
        of libdccl's ``dccl --analyze``."""
        return self._codec.analyze(_type_name(type_name))

    def set_crypto_passphrase(self, passphrase, ids_to_skip=None):
        """Encrypts message bodies (AES-256-CTR keyed by SHA-256 of
        ``passphrase``; headers stay clear) except for the DCCL ids in
        ``ids_to_skip`` (iterable of int). The empty passphrase is a key
        too (SHA-256 of ""), as in libdccl; ``None`` turns encryption off."""
        skip = []
        if ids_to_skip is not None:
            try:
                skip = [int(i) for i in ids_to_skip]
            except TypeError:
                raise TypeError("ids_to_skip is not an iterable of ints") from None
            if any(i < 0 for i in skip):
                raise TypeError("ids_to_skip cannot contain negative values")
        self._codec.set_crypto_passphrase(passphrase, skip)

    def set_strict(self, enabled):
        """Strict mode (bool): out-of-range values, over-long strings and
        arrays raise :class:`DcclOutOfRangeException` instead of being dropped,
        clamped or truncated."""
        self._codec.set_strict(bool(enabled))

    def load_library(self, path):
        """Codec libraries are a C++ feature: raises :class:`DcclException`."""
        raise DcclException("cannot load codec library %s: codecs are built into this package" % path)

    def load_arithmetic_models(self, text):
        """Loads arithmetic-codec models (``dccl.arith.protobuf.ArithmeticModel``
        in text format); returns their names (list of str)."""
        return self._codec.load_arithmetic_models(text)

    def __repr__(self):
        return "dccl.Codec(loaded=%r)" % (self.loaded(),)

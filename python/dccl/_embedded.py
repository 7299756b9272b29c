"""Builds the ``_pb2`` modules of the DCCL option files that ship inside the
native module (``dccl/option_extensions.proto`` and the arithmetic codec's
files), the way generated ``_pb2`` modules build themselves: the serialized
``FileDescriptorProto`` added to the default descriptor pool, then the
descriptors and classes placed in the module. No ``protoc`` is involved: the
bytes are those the Rust library compiled from the same ``.proto`` text.
"""

from google.protobuf import descriptor_pb2 as _descriptor_pb2  # noqa: F401  (descriptor.proto into the pool)
from google.protobuf import descriptor_pool as _descriptor_pool
from google.protobuf.internal import builder as _builder

from . import _dccl


def build(module_globals, file_name):
    """Fills ``module_globals`` (a module's ``globals()``) with the
    descriptors, extensions and classes of the embedded file ``file_name``
    (e.g. ``"dccl/option_extensions.proto"``); returns its FileDescriptor."""
    pool = _descriptor_pool.Default()
    try:
        descriptor = pool.FindFileByName(file_name)
    except KeyError:
        descriptor = pool.AddSerializedFile(_dccl.file_descriptor(file_name))
    module_globals["DESCRIPTOR"] = descriptor
    _builder.BuildMessageAndEnumDescriptors(descriptor, module_globals)
    _builder.BuildTopDescriptorsAndMessages(descriptor, module_globals["__name__"], module_globals)
    return descriptor

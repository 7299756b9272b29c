"""The DCCL options ``(dccl.msg)`` and ``(dccl.field)`` as a protobuf module,
for generated ``_pb2`` modules of files that ``import
"dccl/option_extensions.proto"`` (they import ``dccl.option_extensions_pb2``).

Classes: ``DCCLFieldOptions``, ``DCCLMessageOptions``; extensions: ``field``
(number 1012 of ``google.protobuf.FieldOptions``), ``msg`` (1012 of
``google.protobuf.MessageOptions``).
"""

from dccl import _embedded

_embedded.build(globals(), "dccl/option_extensions.proto")

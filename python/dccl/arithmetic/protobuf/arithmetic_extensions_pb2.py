"""The arithmetic codec's field options (``(dccl.field).(arithmetic)``,
extension 1001 of ``dccl.DCCLFieldOptions``) as a protobuf module, for
generated modules of files importing
``"dccl/arithmetic/protobuf/arithmetic_extensions.proto"``."""

from dccl import _embedded
from dccl import option_extensions_pb2 as _option_extensions_pb2  # noqa: F401  (imported file first)

_embedded.build(globals(), "dccl/arithmetic/protobuf/arithmetic_extensions.proto")

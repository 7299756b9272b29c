"""The arithmetic codec's model message (``dccl.arith.protobuf.ArithmeticModel``)
as a protobuf module."""

from dccl import _embedded
from dccl import option_extensions_pb2 as _option_extensions_pb2  # noqa: F401  (imported file first)

_embedded.build(globals(), "dccl/arithmetic/protobuf/arithmetic.proto")

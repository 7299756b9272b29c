"""Encode and decode time per message through the Python API, on the 1000
version-4 vectors of ../shared/dccl-vectors (the set the Rust benchmark
uses). Prints one line per operation: microseconds per message, the best of
several rounds (the machine is shared: the minimum is the least disturbed).
In the same rounds it times the Rust library alone on the same messages
(``dccl::Codec`` encoding and decoding dynamic messages, in this process)
and prints what the Python API adds over it.

Usage: python python/benches/bench.py [--rounds N] [--passes N] [--message TYPE] [PATH/TO/dccl-vectors]
"""

import argparse
import json
import pathlib
import sys
import time
import warnings

from google.protobuf import text_format

import dccl

HERE = pathlib.Path(__file__).resolve().parent
DEFAULT_VECTORS = HERE.parent.parent.parent / "shared" / "dccl-vectors"


def best_pass(fn, items, passes):
    """Microseconds per item of the fastest of ``passes`` passes of ``fn`` over ``items``."""
    best = float("inf")
    for _ in range(passes):
        start = time.perf_counter_ns()
        for item in items:
            fn(item)
        best = min(best, (time.perf_counter_ns() - start) / len(items) / 1000.0)
    return best


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("vectors", nargs="?", default=str(DEFAULT_VECTORS))
    parser.add_argument("--rounds", type=int, default=4)
    parser.add_argument("--passes", type=int, default=5, help="passes of each operation in a round")
    parser.add_argument("--message", help="only the vectors of this type (e.g. vec.Basic)")
    args = parser.parse_args()
    # The vectors include out-of-range and over-long values on purpose: the
    # codec's warning about each would drown the figures.
    warnings.simplefilter("ignore", dccl.DcclValueChangedWarning)
    vectors = pathlib.Path(args.vectors)
    if not (vectors / "vectors.jsonl").is_file():
        sys.exit("bench.py: no vectors.jsonl in %s" % vectors)

    dccl.loadProtoFile(str(vectors / "vectors.proto"))
    codec = dccl.Codec()
    lines = [json.loads(l) for l in (vectors / "vectors.jsonl").read_text().splitlines() if l.strip()]
    if args.message:
        lines = [v for v in lines if v["message"] == args.message]
        if not lines:
            sys.exit("bench.py: no vector of type %s" % args.message)
    for name in sorted({v["message"] for v in lines}):
        codec.load(name)
    messages = [text_format.Parse(v["input"], dccl.message_class(v["message"])()) for v in lines]
    dicts = [(v["message"], v["input_json"]) for v in lines]
    encoded = [bytes.fromhex(v["hex"]) for v in lines]

    operations = {
        "encode(message)": (codec.encode, messages),
        "decode(bytes) -> message": (codec.decode, encoded),
        "encode_dict(name, dict)": (lambda d: codec.encode_dict(*d), dicts),
        "decode_dict(bytes)": (codec.decode_dict, encoded),
        "protobuf alone: SerializeToString + ParseFromString": (
            lambda m: type(m).FromString(m.SerializePartialToString()),
            messages,
        ),
    }
    # The Rust library on the same messages: dynamic messages parsed from
    # the same protobuf bytes before its clock starts.
    native_types = [codec._codec.message_type(v["message"]) for v in lines]
    native_wires = [m.SerializePartialToString() for m in messages]
    best = {}
    native = (float("inf"), float("inf"))
    # Rounds alternate every operation and the Rust library alone, so that
    # each figure sees the same machine; in a round each runs a few passes
    # in a row (the first one warms the caches), the fastest counting.
    for _ in range(args.rounds):
        for op, (fn, items) in operations.items():
            best[op] = min(best.get(op, float("inf")), best_pass(fn, items, args.passes))
        e, d = codec._codec.time_native(native_types, native_wires, encoded, args.passes)
        native = (min(native[0], e), min(native[1], d))
    print(
        "%d messages (%s), best of %d rounds of %d passes"
        % (len(lines), vectors / "vectors.jsonl", args.rounds, args.passes)
    )
    for op, us in best.items():
        print("%-52s %7.2f us/message" % (op, us))
    print("%-52s %7.2f us/message" % ("Rust library alone: encode", native[0]))
    print("%-52s %7.2f us/message" % ("Rust library alone: decode", native[1]))
    print(
        "%-52s %7.2f us/message"
        % ("Python API over the Rust call: encode(message)", best["encode(message)"] - native[0])
    )
    print(
        "%-52s %7.2f us/message"
        % ("Python API over the Rust call: decode(bytes)", best["decode(bytes) -> message"] - native[1])
    )


if __name__ == "__main__":
    main()

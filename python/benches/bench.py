"""Encode and decode time per message through the Python API, on the 1000
version-4 vectors of ../shared/dccl-vectors (the set the Rust benchmark
uses). Prints one line per operation: microseconds per message, the best of
several rounds (the machine is shared: the minimum is the least disturbed).

Usage: python python/benches/bench.py [--rounds N] [--message TYPE] [PATH/TO/dccl-vectors]
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


def best_per_message(fn, items, rounds):
    best = None
    for _ in range(rounds):
        start = time.perf_counter_ns()
        for item in items:
            fn(item)
        elapsed = time.perf_counter_ns() - start
        best = elapsed if best is None else min(best, elapsed)
    return best / len(items) / 1000.0


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("vectors", nargs="?", default=str(DEFAULT_VECTORS))
    parser.add_argument("--rounds", type=int, default=20)
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

    results = {
        "encode(message)": best_per_message(codec.encode, messages, args.rounds),
        "decode(bytes) -> message": best_per_message(codec.decode, encoded, args.rounds),
        "encode_dict(name, dict)": best_per_message(lambda d: codec.encode_dict(*d), dicts, args.rounds),
        "decode_dict(bytes)": best_per_message(codec.decode_dict, encoded, args.rounds),
        "protobuf alone: SerializeToString + ParseFromString": best_per_message(
            lambda m: type(m).FromString(m.SerializePartialToString()), messages, args.rounds
        ),
    }
    print("%d messages (%s), best of %d rounds" % (len(lines), vectors / "vectors.jsonl", args.rounds))
    for op, us in results.items():
        print("%-52s %7.2f us/message" % (op, us))


if __name__ == "__main__":
    main()

"""The package reads and writes the protobuf bytes that cross between Python
and the codec from a plan per message type (python/src/wire.rs) rather
than through prost-reflect; `check_wire` compares the two on one message
(same message read, or a fall-back to prost-reflect; same bytes written).
Here on every vector's message and its decoded form, on other encodings of
the same messages (repeated fields packed, fields out of order, a message
given twice, an unknown field) and on damaged bytes."""

import json
import random

import pytest
from google.protobuf import text_format

import dccl

TYPES = ("vec.Basic", "vec.Lists", "vec.Nested", "vec.Wide", "vec.Special")


@pytest.fixture(scope="module")
def loaded(vectors_dir):
    dccl.loadProtoFile(str(vectors_dir / "vectors.proto"))
    codec = dccl.Codec()
    for name in TYPES:
        codec.load(name)
    lines = [json.loads(l) for l in (vectors_dir / "vectors.jsonl").read_text().splitlines() if l.strip()]
    return codec, lines


def varint(v):
    out = bytearray()
    while v >= 0x80:
        out.append((v & 0x7F) | 0x80)
        v >>= 7
    out.append(v)
    return bytes(out)


def fields_of(data):
    """The top-level fields of protobuf bytes as (number, wire type, raw bytes of key and value)."""
    out, i = [], 0
    while i < len(data):
        start, key, shift = i, 0, 0
        while True:
            b = data[i]
            i += 1
            key |= (b & 0x7F) << shift
            shift += 7
            if b < 0x80:
                break
        wt = key & 7
        if wt == 0:
            while data[i] >= 0x80:
                i += 1
            i += 1
        elif wt == 1:
            i += 8
        elif wt == 5:
            i += 4
        else:
            n, shift = 0, 0
            while True:
                b = data[i]
                i += 1
                n |= (b & 0x7F) << shift
                shift += 7
                if b < 0x80:
                    break
            i += n
        out.append((key >> 3, wt, data[start:i]))
    return out


def test_vectors_and_their_decoded_forms(loaded):
    codec, lines = loaded
    native = codec._codec
    handles = {name: native.message_type(name) for name in TYPES}
    checked = 0
    for v in lines:
        msg = text_format.Parse(v["input"], dccl.message_class(v["message"])())
        native.check_wire(handles[v["message"]], msg.SerializePartialToString())
        name, wire = native.decode(bytes.fromhex(v["hex"]))
        assert name == v["message"]
        native.check_wire(handles[name], wire)
        # What the package's decode returns parses to the same message.
        assert codec.decode(bytes.fromhex(v["hex"])) == type(msg).FromString(wire)
        checked += 1
    assert checked == 1000


def test_other_encodings_of_the_same_messages(loaded):
    codec, lines = loaded
    native = codec._codec
    rng = random.Random(5)
    cases = 0
    for v in lines:
        handle = native.message_type(v["message"])
        msg = text_format.Parse(v["input"], dccl.message_class(v["message"])())
        fields = fields_of(msg.SerializePartialToString())
        if not fields:
            continue
        # Fields out of order, one field given twice (a scalar: the last
        # counts; a message: merged), an unknown field (kept by prost-reflect).
        shuffled = fields[:]
        rng.shuffle(shuffled)
        twice = fields + [fields[rng.randrange(len(fields))]]
        unknown = fields + [(99, 0, varint(99 << 3) + varint(7))]
        for variant in (shuffled, twice, unknown):
            native.check_wire(handle, b"".join(raw for _, _, raw in variant))
            cases += 1
        # Repeated varint fields of the same number packed into one.
        by_number = {}
        for number, wt, raw in fields:
            by_number.setdefault((number, wt), []).append(raw)
        packed = b""
        for (number, wt), raws in sorted(by_number.items()):
            if wt == 0 and len(raws) > 1:
                payload = b"".join(r[len(varint(number << 3)) :] for r in raws)
                packed += varint(number << 3 | 2) + varint(len(payload)) + payload
            else:
                packed += b"".join(raws)
        native.check_wire(handle, packed)
        cases += 1
    assert cases > 3000


def test_damaged_bytes(loaded):
    codec, lines = loaded
    native = codec._codec
    rng = random.Random(6)
    for v in lines[:300]:
        handle = native.message_type(v["message"])
        wire = text_format.Parse(v["input"], dccl.message_class(v["message"])()).SerializePartialToString()
        for _ in range(10):
            damaged = bytearray(wire)
            if damaged and rng.random() < 0.5:
                damaged[rng.randrange(len(damaged))] = rng.randrange(256)
            else:
                damaged = damaged[: rng.randrange(len(damaged) + 1)]
            native.check_wire(handle, bytes(damaged))
        native.check_wire(handle, bytes(rng.randrange(256) for _ in range(rng.randrange(30))))

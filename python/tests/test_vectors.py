"""Every reference vector of ../shared/dccl-vectors through the Python API:
the message read from its text form and encoded gives exactly the reference
bytes; the reference bytes decode to the reference values, as protobuf
message objects, as dicts and as text; the JSON input encodes the same.
"""

import json

import pytest
from google.protobuf import json_format, text_format

import dccl
from compare import same

# The vectors include values out of their bounds on purpose: what libdccl
# sends for them is what is compared, not the warning each one gives.
pytestmark = pytest.mark.filterwarnings("ignore::dccl.DcclValueChangedWarning")

PASSPHRASE = "correct horse battery staple"


def read_vectors(path):
    with open(path, encoding="utf-8") as f:
        return [json.loads(line) for line in f if line.strip()]


def normalized(cls, values):
    """A JSON-shaped dict through the message class and back: float32
    rounding, defaults and spelling made the same on both sides."""
    msg = json_format.ParseDict(values, cls())
    return json_format.MessageToDict(msg, preserving_proto_field_name=True)


def as_dict(msg):
    return json_format.MessageToDict(msg, preserving_proto_field_name=True)


def check_file(vectors_dir, proto, vectors, passphrase=None):
    dccl.loadProtoFile(str(vectors_dir / proto))
    codec = dccl.Codec()
    if passphrase:
        codec.set_crypto_passphrase(passphrase)
    lines = read_vectors(vectors_dir / vectors)
    for name in sorted({v["message"] for v in lines}):
        codec.load(name)
    failures = []
    for n, v in enumerate(lines, 1):
        name = v["message"]
        cls = dccl.message_class(name)
        where = "%s line %d (%s)" % (vectors, n, name)

        msg = text_format.Parse(v["input"], cls())
        try:
            got = codec.encode(msg).hex()
            if got != v["hex"]:
                failures.append("%s: encode gave %s, want %s" % (where, got, v["hex"]))
        except dccl.DcclException as e:
            failures.append("%s: encode raised %s" % (where, e))
        try:
            got = codec.encode_dict(name, v["input_json"]).hex()
            if got != v["hex"]:
                failures.append("%s: encode_dict gave %s, want %s" % (where, got, v["hex"]))
        except dccl.DcclException as e:
            failures.append("%s: encode_dict raised %s" % (where, e))

        data = bytes.fromhex(v["hex"])
        want = normalized(cls, v["decoded_json"])
        decoded = codec.decode(data)
        if type(decoded).DESCRIPTOR.full_name != name or not same(as_dict(decoded), want):
            failures.append("%s: decode gave %s, want %s" % (where, as_dict(decoded), want))
        if not same(normalized(cls, codec.decode_dict(data)), want):
            failures.append("%s: decode_dict gave %s" % (where, codec.decode_dict(data)))
        if "decoded_text" in v and codec.decode_text(data) != v["decoded_text"]:
            failures.append("%s: decode_text gave %r" % (where, codec.decode_text(data)))
        if codec.id(data) != codec.id(name):
            failures.append("%s: id of the bytes differs from the type's" % where)
    assert len(lines) > 100, "%s: only %d vectors" % (vectors, len(lines))
    assert not failures, "%d of %d vectors failed:\n%s" % (len(failures), len(lines), "\n".join(failures[:12]))
    return len(lines)


def test_version4_vectors(vectors_dir):
    check_file(vectors_dir, "vectors.proto", "vectors.jsonl")


def test_legacy_version2_and_3_vectors(vectors_dir):
    check_file(vectors_dir, "legacy.proto", "legacy.jsonl")


def test_encrypted_vectors(vectors_dir):
    check_file(vectors_dir, "vectors.proto", "vectors-encrypted.jsonl", PASSPHRASE)


def test_encrypted_vectors_do_not_decode_without_the_passphrase(vectors_dir):
    dccl.loadProtoFile(str(vectors_dir / "vectors.proto"))
    codec = dccl.Codec()
    lines = read_vectors(vectors_dir / "vectors-encrypted.jsonl")
    for name in sorted({v["message"] for v in lines}):
        codec.load(name)
    differ = 0
    for v in lines:
        try:
            plain = codec.decode_dict(bytes.fromhex(v["hex"]))
        except dccl.DcclException:
            differ += 1
            continue
        cls = dccl.message_class(v["message"])
        if not same(normalized(cls, plain), normalized(cls, v["decoded_json"])):
            differ += 1
    assert differ > len(lines) * 0.9


def test_arithmetic_vectors_in_order(vectors_dir):
    arith = vectors_dir / "arithmetic"
    if not (arith / "vectors.jsonl").is_file():
        pytest.skip("SKIPPED: %s absent" % arith)
    dccl.loadProtoFile(str(arith / "arithmetic.proto"))
    models = (arith / "models.txt").read_text()
    sender, receiver = dccl.Codec(), dccl.Codec()
    lines = read_vectors(arith / "vectors.jsonl")
    for codec in (sender, receiver):
        assert codec.load_arithmetic_models(models)
        for name in sorted({v["message"] for v in lines}):
            codec.load(name)
    failures = []
    for v in sorted(lines, key=lambda v: v["seq"]):
        cls = dccl.message_class(v["message"])
        got = sender.encode(text_format.Parse(v["input"], cls())).hex()
        if got != v["hex"]:
            failures.append("seq %d: encode gave %s, want %s" % (v["seq"], got, v["hex"]))
        decoded = receiver.decode(bytes.fromhex(v["hex"]))
        if not same(as_dict(decoded), normalized(cls, v["decoded_json"])):
            failures.append("seq %d: decode gave %s" % (v["seq"], as_dict(decoded)))
    assert len(lines) > 10
    assert not failures, "\n".join(failures[:12])


def test_definition_hashes(vectors_dir):
    dccl.loadProtoFile(str(vectors_dir / "vectors.proto"))
    dccl.loadProtoFile(str(vectors_dir / "legacy.proto"))
    codec = dccl.Codec()
    checked = 0
    for line in (vectors_dir / "hashes.txt").read_text().splitlines():
        if not line.strip():
            continue
        name, want = line.split()
        codec.load(name)
        assert "0x%016x" % codec.hash(name) == want, name
        checked += 1
    assert checked >= 5


def test_analyze_matches_the_reference(vectors_dir):
    dccl.loadProtoFile(str(vectors_dir / "vectors.proto"))
    codec = dccl.Codec()
    text = (vectors_dir / "analyze.txt").read_text()
    checked = 0
    for name in ("vec.Basic", "vec.Lists", "vec.Nested", "vec.Wide", "vec.Special"):
        codec.load(name)
        report = codec.analyze(name)
        assert report.strip() in text, name
        checked += 1
    assert checked == 5

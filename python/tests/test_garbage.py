"""Bad input gives a DcclException, never a panic (which would surface as
pyo3's PanicException, not a DcclException): random and truncated bytes
through decode, decode_all and id; random values through encode."""

import random

import pytest

import dccl


@pytest.fixture(scope="module")
def vector_codec(vectors_dir):
    dccl.loadProtoFile(str(vectors_dir / "vectors.proto"))
    codec = dccl.Codec()
    for name in ("vec.Basic", "vec.Lists", "vec.Nested", "vec.Wide", "vec.Special"):
        codec.load(name)
    return codec


def test_random_and_truncated_bytes(vector_codec, vectors_dir):
    rng = random.Random(17)
    ids = [10, 11, 12, 13, 14]  # the vectors' DCCL ids, so bodies get decoded
    cases = 0
    for _ in range(3000):
        data = bytes([rng.choice(ids) << 1]) + bytes(rng.randrange(256) for _ in range(rng.randrange(0, 40)))
        for fn in (vector_codec.decode, vector_codec.decode_all, vector_codec.decode_dict, vector_codec.id):
            try:
                fn(data)
            except dccl.DcclException:
                pass
            cases += 1
    assert cases == 12000


def test_random_values_encode_or_raise(vector_codec):
    rng = random.Random(18)
    cls = dccl.message_class("vec.Basic")
    fields = [f for f in cls.DESCRIPTOR.fields if f.type in (f.TYPE_INT32, f.TYPE_DOUBLE, f.TYPE_UINT32)]
    assert fields
    vector_codec.set_strict(True)
    try:
        raised = 0
        for _ in range(2000):
            msg = cls()
            for f in fields:
                if rng.random() < 0.7:
                    v = rng.uniform(-1e12, 1e12) if f.type == f.TYPE_DOUBLE else rng.randrange(0, 2**31)
                    setattr(msg, f.name, v)
            try:
                data = vector_codec.encode(msg)
                vector_codec.decode(data)
            except dccl.DcclException:
                raised += 1
        assert raised > 0
    finally:
        vector_codec.set_strict(False)

"""Dynamic conditions (`(dccl.field).dynamic_conditions`) through the
package: libdccl 4.2's (with Lua) encodings of the message set the Rust
crate is checked with, a left-out value warned about, a condition that
fails raising an error naming message, field and script."""

import warnings

import pytest

import dccl

from conftest import WORKSPACE

CONDITIONS = WORKSPACE / "dccl" / "tests" / "data" / "dynamic-conditions"


@pytest.fixture(scope="module")
def codec():
    names = dccl.loadProtoFile(str(CONDITIONS / "conditions.proto"))
    assert "goby.test.conditions.Survey" in names
    c = dccl.Codec()
    for name in ("Survey", "Status", "Log", "Legacy"):
        c.load("goby.test.conditions." + name)
    return c


def reference_cases(limit):
    """(type, text, hex, decoded) of the first inputs libdccl encodes and decodes."""
    inputs = (CONDITIONS / "input.txt").read_text().splitlines()
    answers = (CONDITIONS / "expected.txt").read_text().splitlines()
    out = []
    for line, answer in zip(inputs, answers):
        if not answer.startswith("ok "):
            continue
        hex_, decoded, _ = answer[3:].split("\t")
        if decoded.startswith("!"):
            continue
        ty, text = line[1:].split("|", 1)
        out.append((ty, text.strip(), hex_, decoded))
        if len(out) == limit:
            break
    return out


def test_encodings_are_libdccl_s(codec):
    from google.protobuf import text_format

    cases = reference_cases(200)
    assert len(cases) == 200
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", dccl.DcclValueChangedWarning)
        for ty, text, hex_, _ in cases:
            msg = text_format.Parse(text, dccl.message_class(ty)())
            assert codec.encode(msg).hex() == hex_, text
            assert codec.decode(bytes.fromhex(hex_)).DESCRIPTOR.full_name == ty


def test_a_left_out_value_is_a_change_and_a_failing_condition_an_error(codec, tmp_path):
    survey = dccl.message_class("goby.test.conditions.Survey")
    sensor = dccl.message_class("goby.test.conditions.Survey.Sensor")
    # `heading` is only sent in MODE_LINE.
    msg = survey(mode=1, speed=3, heading=90, sensor=sensor(use=1, gain=3))
    changes = codec.check(msg)
    assert ("heading", 'omit_if "this.mode ~= \'MODE_LINE\'" is true: not sent (the condition leaves the field out)') in changes
    path = tmp_path / "condfail.proto"
    path.write_text(
        'syntax = "proto2"; import "dccl/option_extensions.proto"; package condfail;\n'
        "message M { option (dccl.msg) = { id: 50 max_bytes: 8 codec_version: 4 };\n"
        '  optional int32 a = 1 [(dccl.field) = { min: 0 max: 9 dynamic_conditions { omit_if: "this.b + 1 > 2" } }];\n'
        "  optional int32 b = 2 [(dccl.field) = { min: 0 max: 9 }]; }\n"
    )
    dccl.loadProtoFile(str(path))
    c = dccl.Codec()
    c.load("condfail.M")
    with pytest.raises(dccl.DcclException, match=r"condfail\.M.*field a.*this\.b \+ 1 > 2.*nil"):
        c.encode(dccl.message_class("condfail.M")(a=1))

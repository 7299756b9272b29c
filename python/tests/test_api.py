"""The package's API beyond the vectors: the reference binding's calls,
errors that name message and field, JSON and dict in and out, frames."""

import textwrap
import warnings

import pytest

import dccl

PING = textwrap.dedent(
    """
    syntax = "proto2";
    import "dccl/option_extensions.proto";
    package apitest;
    message Ping {
      option (dccl.msg) = { id: 20 max_bytes: 32 codec_version: 4 };
      required int32 src = 1 [(dccl.field) = { min: 0 max: 31 in_head: true }];
      optional double range = 2 [(dccl.field) = { min: 0 max: 5000 precision: 1 }];
      optional string note = 3 [(dccl.field).max_length = 8];
      repeated int32 hops = 4 [(dccl.field) = { min: 0 max: 7 max_repeat: 3 }];
      optional int64 stamp = 5 [(dccl.field) = { min: 0 max: 1000000 }];
    }
    message Pong {
      option (dccl.msg) = { id: 21 max_bytes: 8 codec_version: 4 };
      required bool ok = 1;
    }
    """
)


@pytest.fixture(scope="module")
def ping_proto(tmp_path_factory):
    path = tmp_path_factory.mktemp("protos") / "apitest_ping.proto"
    path.write_text(PING)
    names = dccl.loadProtoFile(str(path))
    assert names == ["apitest.Ping", "apitest.Pong"]
    return path


@pytest.fixture
def codec(ping_proto):
    c = dccl.Codec()
    c.load("apitest.Ping")
    c.load("apitest.Pong")
    return c


def ping(**kw):
    return dccl.message_class("apitest.Ping")(**kw)


def test_encode_decode_round_trip_with_rounding(codec):
    data = codec.encode(ping(src=3, range=1234.56, note="hi"))
    assert isinstance(data, bytes) and len(data) == codec.size(ping(src=3, range=1234.56, note="hi"))
    back = codec.decode(data)
    assert back.src == 3 and back.note == "hi"
    assert back.range == pytest.approx(1234.6)
    assert codec.decode(bytearray(data)) == back
    assert codec.decode(memoryview(data)) == back


def test_id_of_an_unknown_name_raises(codec):
    # A str is a type name, never encoded bytes: a misspelt name is an error.
    with pytest.raises(dccl.DcclException, match=r"apitest\.Pingg"):
        codec.id("apitest.Pingg")
    with pytest.raises(dccl.DcclException):
        codec.id("\x28\x00")
    assert codec.id(codec.encode(ping(src=1))) == 20


def test_include_path_must_be_a_directory(tmp_path):
    with pytest.raises(dccl.DcclException, match="no_such_dir"):
        dccl.addProtoIncludePath(tmp_path / "no_such_dir")
    (tmp_path / "plain_file").write_text("")
    with pytest.raises(dccl.DcclException, match="plain_file"):
        dccl.addProtoIncludePath(str(tmp_path / "plain_file"))
    dccl.addProtoIncludePath(tmp_path)


CLASH = textwrap.dedent(
    """
    syntax = "proto2";
    import "dccl/option_extensions.proto";
    package apiclash;
    message Thing {
      option (dccl.msg) = { id: 50 max_bytes: 8 codec_version: 4 };
      required int32 x = 1 [(dccl.field) = { min: 0 max: %d }];
      message Inner { optional int32 y = 1 [(dccl.field) = { min: 0 max: %d }]; }
      optional Inner inner = 2;
    }
    """
)


def test_clashing_definitions_are_refused(tmp_path):
    for d in ("a", "b", "c", "d"):
        (tmp_path / d).mkdir()
    first = tmp_path / "a" / "apiclash.proto"
    first.write_text(CLASH % (10, 10))
    assert dccl.loadProtoFile(first) == ["apiclash.Thing", "apiclash.Thing.Inner"]
    # The same file again, and an identical copy elsewhere, are fine.
    assert dccl.loadProtoFile(first) == ["apiclash.Thing", "apiclash.Thing.Inner"]
    copy = tmp_path / "b" / "apiclash_copy.proto"
    copy.write_text(CLASH % (10, 10))
    dccl.loadProtoFile(copy)
    # Another definition of the same type, under another file name...
    other = tmp_path / "c" / "apiclash_other.proto"
    other.write_text(CLASH % (20, 10))
    with pytest.raises(dccl.DcclException, match=r"apiclash\.Thing\b"):
        dccl.loadProtoFile(other)
    # ... or the same file name: the nested type that differs is named.
    same_name = tmp_path / "d" / "apiclash.proto"
    same_name.write_text(CLASH % (10, 20))
    with pytest.raises(dccl.DcclException, match=r"apiclash\.Thing\.Inner"):
        dccl.loadProtoFile(same_name)
    # The first definition stays.
    c = dccl.Codec()
    c.load("apiclash.Thing")
    thing = dccl.message_class("apiclash.Thing")
    assert [field for field, _ in c.check(thing(x=15))] == ["x"]  # max 10, not 20


def test_check_and_value_changed_warnings(codec):
    changed = ping(src=1, range=9999, note="far too long")
    changes = codec.check(changed)
    assert [field for field, _ in changes] == ["range", "note"]
    assert all(isinstance(reason, str) and reason for _, reason in changes)
    with pytest.warns(dccl.DcclValueChangedWarning) as record:
        codec.encode(changed)
    texts = [str(w.message) for w in record if issubclass(w.category, dccl.DcclValueChangedWarning)]
    assert len(texts) == 2
    assert "apitest.Ping" in texts[0] and "field range" in texts[0]
    assert "field note" in texts[1]
    assert codec.check(ping(src=1)) == []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        codec.encode(ping(src=1))
        # Strict mode raises instead of warning; check still reports.
        codec.set_strict(True)
        try:
            with pytest.raises(dccl.DcclOutOfRangeException):
                codec.encode(changed)
            assert [field for field, _ in codec.check(changed)] == ["range", "note"]
        finally:
            codec.set_strict(False)


def test_ids_of_types_and_bytes(codec):
    data = codec.encode(ping(src=1))
    assert codec.id(data) == 20
    assert codec.id("apitest.Ping") == 20
    assert codec.id(dccl.message_class("apitest.Pong")) == 21
    assert codec.id(ping(src=1)) == 20


def test_sizes_hash_and_analyze(codec):
    assert codec.max_size("apitest.Ping") >= codec.min_size("apitest.Ping") > 0
    assert codec.max_size("apitest.Ping") <= 32
    h = codec.hash("apitest.Ping")
    assert isinstance(h, int) and 0 <= h < 2**64
    report = codec.analyze("apitest.Ping")
    assert "apitest.Ping" in report and "range" in report and "0x%016x" % h in report


def test_decode_all_splits_a_frame(codec):
    pong = dccl.message_class("apitest.Pong")(ok=True)
    frame = codec.encode(ping(src=2, hops=[1, 2])) + codec.encode(pong) + codec.encode(ping(src=5))
    msgs = codec.decode_all(frame)
    assert [type(m).DESCRIPTOR.full_name for m in msgs] == ["apitest.Ping", "apitest.Pong", "apitest.Ping"]
    assert list(msgs[0].hops) == [1, 2] and msgs[1].ok and msgs[2].src == 5


def test_json_and_dict_in_and_out(codec):
    data = codec.encode_dict("apitest.Ping", {"src": 4, "range": 10.04, "note": "abc", "stamp": 12345})
    assert data == codec.encode(ping(src=4, range=10.04, note="abc", stamp=12345))
    assert codec.encode_json("apitest.Ping", '{"src": 4, "range": 10.04, "note": "abc", "stamp": "12345"}') == data
    assert codec.decode_dict(data) == {"src": 4, "range": 10.0, "note": "abc", "stamp": 12345}
    name, text = codec.decode_json(data, with_name=True)
    assert name == "apitest.Ping" and '"note":"abc"' in text
    assert codec.decode_text(data) == 'src: 4 range: 10 note: "abc" stamp: 12345'


def test_bad_json_names_the_message(codec):
    with pytest.raises(dccl.DcclException, match="apitest.Ping"):
        codec.encode_json("apitest.Ping", '{"src": "many"}')
    with pytest.raises(dccl.DcclException, match="apitest.Ping"):
        codec.encode_dict("apitest.Ping", {"nope": 1})


def test_missing_required_field_names_message_and_field(codec):
    with pytest.raises(dccl.DcclException, match=r"apitest\.Ping, field src") as e:
        codec.encode(ping(range=3))
    assert not isinstance(e.value, dccl.DcclOutOfRangeException)


@pytest.mark.filterwarnings("ignore::dccl.DcclValueChangedWarning")
def test_out_of_range_is_dropped_or_truncated_unless_strict(codec):
    lenient = codec.decode(codec.encode(ping(src=1, range=9999, note="far too long", hops=[1, 2, 3, 4])))
    assert not lenient.HasField("range")
    assert lenient.note == "far too "
    assert list(lenient.hops) == [1, 2, 3]
    codec.set_strict(True)
    with pytest.raises(dccl.DcclOutOfRangeException, match=r"apitest\.Ping, field range"):
        codec.encode(ping(src=1, range=9999))
    with pytest.raises(dccl.DcclOutOfRangeException, match=r"field note"):
        codec.encode(ping(src=1, note="far too long"))
    with pytest.raises(dccl.DcclException, match=r"field src"):
        codec.encode(ping(range=1))  # missing, not out of range: the base class
    codec.set_strict(False)
    assert codec.encode(ping(src=1, range=9999))


def test_decode_errors(codec):
    with pytest.raises(dccl.DcclException, match="id 99"):
        codec.decode(bytes([99 << 1, 0, 0]))
    with pytest.raises(dccl.DcclException, match="apitest.Ping"):
        codec.decode(codec.encode(ping(src=1, note="abcdefgh"))[:2])
    with pytest.raises(dccl.DcclException):
        codec.decode(b"")


def test_unknown_and_unloaded_types(ping_proto):
    c = dccl.Codec()
    with pytest.raises(LookupError):
        c.load("apitest.NoSuchType")
    with pytest.raises(dccl.DcclException, match="apitest.Ping has not been loaded"):
        c.encode(ping(src=1))
    with pytest.raises(dccl.DcclException, match="id 20 has not been loaded"):
        c.decode(bytes([40, 0, 0]))
    with pytest.raises(KeyError):
        dccl.message_class("apitest.NoSuchType")


def test_crypto_with_skipped_ids(codec, ping_proto):
    clear = codec.encode(ping(src=3, range=100))
    codec.set_crypto_passphrase("secret")
    hidden = codec.encode(ping(src=3, range=100))
    assert hidden != clear and hidden[:2] == clear[:2]  # header (id, src) stays clear
    assert codec.decode(hidden).range == 100
    other = dccl.Codec()
    other.load("apitest.Ping")
    try:
        assert other.decode(hidden).range != 100
    except dccl.DcclException:
        pass  # the garbled body may not even decode
    codec.set_crypto_passphrase("secret", ids_to_skip=[20])
    assert codec.encode(ping(src=3, range=100)) == clear
    with pytest.raises(TypeError):
        codec.set_crypto_passphrase("secret", ids_to_skip=[-1])
    codec.set_crypto_passphrase(None)
    assert codec.encode(ping(src=3, range=100)) == clear


def test_empty_passphrase_encrypts_as_the_reference_does(codec):
    # libdccl keys AES with SHA-256 of the passphrase, the empty one too.
    clear = codec.encode(ping(src=3, range=100))
    codec.set_crypto_passphrase("")
    hidden = codec.encode(ping(src=3, range=100))
    assert hidden != clear and hidden[:2] == clear[:2]
    other = dccl.Codec()
    other.load("apitest.Ping")
    other.set_crypto_passphrase("")
    assert other.decode(hidden).range == 100


def test_invalid_definition_names_message_and_field(tmp_path):
    path = tmp_path / "apitest_bad.proto"
    path.write_text(
        'syntax = "proto2"; import "dccl/option_extensions.proto"; package apibad;\n'
        "message Big { option (dccl.msg) = { id: 30 max_bytes: 2 codec_version: 4 };\n"
        "  required int32 a = 1 [(dccl.field) = { min: 0 max: 100000 }];\n"
        "  required int32 b = 2; }\n"
    )
    dccl.loadProtoFile(path)
    with pytest.raises(dccl.DcclException, match=r"apibad\.Big.*field b"):
        dccl.Codec().load("apibad.Big")


def test_proto_syntax_error_names_the_file(tmp_path):
    path = tmp_path / "apitest_syntax.proto"
    path.write_text('syntax = "proto2";\nmessage Broken {\n  required int32 = 1;\n}\n')
    with pytest.raises(dccl.DcclException, match=r"apitest_syntax\.proto:3:18: expected an identifier"):
        dccl.loadProtoFile(str(path))
    with pytest.raises(dccl.DcclException, match="no such file"):
        dccl.loadProtoFile(str(tmp_path / "absent.proto"))


def test_include_path_resolves_imports(tmp_path):
    lib = tmp_path / "lib" / "apiinc"
    lib.mkdir(parents=True)
    (lib / "units.proto").write_text('syntax = "proto2"; package apiinc; enum Unit { M = 1; FT = 2; }\n')
    user = tmp_path / "user"
    user.mkdir()
    (user / "apiinc_depth.proto").write_text(
        'syntax = "proto2"; import "dccl/option_extensions.proto"; import "apiinc/units.proto";\n'
        "package apiinc; message Depth { option (dccl.msg) = { id: 40 max_bytes: 4 codec_version: 4 };\n"
        "  required Unit unit = 1; }\n"
    )
    with pytest.raises(dccl.DcclException, match="apiinc/units.proto"):
        dccl.loadProtoFile(str(user / "apiinc_depth.proto"))
    dccl.addProtoIncludePath(str(tmp_path / "lib"))
    dccl.loadProtoFile(str(user / "apiinc_depth.proto"))
    c = dccl.Codec()
    c.load("apiinc.Depth")
    cls = dccl.message_class("apiinc.Depth")
    assert c.decode(c.encode(cls(unit=2))).unit == 2


def test_reference_constructor_and_unsupported_parts():
    dccl.Codec()
    dccl.Codec("dccl.default.id")
    dccl.Codec(id_codec=None, library_path=None)
    with pytest.raises(dccl.DcclException):
        dccl.Codec(library_path="/usr/lib/libmycodecs.so")
    with pytest.raises(dccl.DcclException):
        dccl.Codec(id_codec="my.id")
    with pytest.raises(dccl.DcclException):
        dccl.Codec().load_library("/usr/lib/libmycodecs.so")


def test_exceptions_are_the_reference_names():
    assert issubclass(dccl.DcclException, Exception)
    assert issubclass(dccl.DcclOutOfRangeException, dccl.DcclException)


def test_shipped_option_extensions_module():
    from google.protobuf import descriptor_pb2

    from dccl import option_extensions_pb2 as opts

    assert opts.DESCRIPTOR.name == "dccl/option_extensions.proto"
    assert opts.field.number == 1012 and opts.msg.number == 1012
    assert opts.field.containing_type is descriptor_pb2.FieldOptions.DESCRIPTOR
    o = opts.DCCLFieldOptions(min=0, max=10, precision=2)
    assert opts.DCCLFieldOptions.FromString(o.SerializeToString()) == o
    fo = descriptor_pb2.FieldOptions()
    fo.Extensions[opts.field].max_length = 8
    assert descriptor_pb2.FieldOptions.FromString(fo.SerializeToString()).Extensions[opts.field].max_length == 8

    from dccl.arithmetic.protobuf import arithmetic_extensions_pb2, arithmetic_pb2

    assert arithmetic_pb2.ArithmeticModel.DESCRIPTOR.full_name == "dccl.arith.protobuf.ArithmeticModel"
    assert arithmetic_extensions_pb2.DESCRIPTOR.name.endswith("arithmetic_extensions.proto")


def test_message_types_built_from_python_descriptors():
    """A type defined only in Python (no .proto, no protoc): its file goes to
    the codec through the descriptor, options included."""
    from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

    from dccl import option_extensions_pb2 as opts

    f = descriptor_pb2.FileDescriptorProto(
        name="apitest/py_only.proto", package="apipy", syntax="proto2",
        dependency=["dccl/option_extensions.proto"],
    )
    m = f.message_type.add(name="Beacon")
    m.options.Extensions[opts.msg].id = 50
    m.options.Extensions[opts.msg].max_bytes = 8
    m.options.Extensions[opts.msg].codec_version = 4
    fld = m.field.add(name="depth", number=1, type=descriptor_pb2.FieldDescriptorProto.TYPE_DOUBLE,
                      label=descriptor_pb2.FieldDescriptorProto.LABEL_REQUIRED)
    fld.options.Extensions[opts.field].min = 0
    fld.options.Extensions[opts.field].max = 100
    fld.options.Extensions[opts.field].precision = 1
    descriptor_pool.Default().Add(f)
    cls = message_factory.GetMessageClass(descriptor_pool.Default().FindMessageTypeByName("apipy.Beacon"))
    c = dccl.Codec()
    c.load(cls)
    data = c.encode(cls(depth=12.34))
    assert len(data) == 3  # 1 byte of id, 10 bits of depth
    back = c.decode(data)
    assert type(back) is cls and back.depth == pytest.approx(12.3)


def test_a_time_the_receiver_would_decode_on_another_date_is_warned(protos_dir):
    import time

    dccl.loadProtoFile(str(protos_dir / "goby" / "example" / "navigation.proto"))
    codec = dccl.Codec()
    codec.load("goby.example.NavigationReport")
    report = dccl.message_class("goby.example.NavigationReport")
    # 2023: the time codec sends the time of day, the receiver restores today's date.
    old = report(source=1, destination=2, time=1.7e9, x=450, y=550, z=-100)
    assert [field for field, _ in codec.check(old)] == ["time"]
    with pytest.warns(dccl.DcclValueChangedWarning, match="time"):
        codec.encode(old)
    now = report(source=1, destination=2, time=time.time(), x=450, y=550, z=-100)
    assert codec.check(now) == []
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        codec.encode(now)


OMIT = textwrap.dedent(
    """
    syntax = "proto2";
    import "dccl/option_extensions.proto";
    package omittest;
    message Bare {
      option (dccl.msg) = { id: 40 max_bytes: 8 codec_version: 4 omit_id: true };
      required int32 x = 1 [(dccl.field) = { min: 0 max: 100 }];
      optional string tag = 2 [(dccl.field).max_length = 4];
    }
    """
)


def test_an_omit_id_type_decodes_by_naming_its_type(tmp_path):
    path = tmp_path / "omittest_bare.proto"
    path.write_text(OMIT)
    assert dccl.loadProtoFile(path) == ["omittest.Bare"]
    codec = dccl.Codec()
    codec.load("omittest.Bare")
    cls = dccl.message_class("omittest.Bare")
    msg = cls(x=42, tag="ab")
    data = codec.encode(msg)
    # The type as the second argument (where the reference binding has
    # header_only), by keyword, as a class, a message or a Descriptor.
    assert codec.decode(data, "omittest.Bare") == msg
    assert codec.decode(data, type_name="omittest.Bare") == msg
    assert codec.decode(data, cls) == msg
    assert codec.decode(data, msg) == msg
    assert codec.decode(data, cls.DESCRIPTOR) == msg
    assert codec.decode_dict(data, type_name="omittest.Bare") == {"x": 42, "tag": "ab"}
    assert codec.decode_json(data, True, "omittest.Bare")[0] == "omittest.Bare"
    assert codec.decode_text(data, "omittest.Bare") == 'x: 42 tag: "ab"'
    # Without the type the bytes have no id to read: the error says how.
    with pytest.raises(dccl.DcclException, match=r'omit_id.*decode\(data, "omittest\.Bare"\)'):
        codec.decode(data)
    # The reference's header_only is still refused, and the type is given once.
    with pytest.raises(dccl.DcclException, match="not supported"):
        codec.decode(data, True)
    with pytest.raises(TypeError, match="twice"):
        codec.decode(data, "omittest.Bare", type_name="omittest.Bare")


def test_a_type_given_to_decode_must_match_the_id_read(codec):
    data = codec.encode(ping(src=3))
    assert codec.decode(data, "apitest.Ping").src == 3
    with pytest.raises(dccl.DcclException, match="received id 20, expected 21"):
        codec.decode(data, "apitest.Pong")


def test_value_changed_warnings_point_at_the_caller_and_follow_the_filters(codec):
    changed = ping(src=1, range=9999)
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        data = codec.encode(changed)
    assert [w.filename for w in record] == [__file__]
    assert "field range" in str(record[0].message)
    # Ignored (the documented way to silence them): the same bytes, no
    # warning; the changes are not made at all.
    with warnings.catch_warnings(record=True) as record:
        warnings.simplefilter("always")
        warnings.simplefilter("ignore", dccl.DcclValueChangedWarning)
        assert codec.encode(changed) == data
        assert record == []
        # A filter for one module (this one): the changes are made again,
        # and warned; the same filter for another module lets the ignore
        # filter decide.
        warnings.filterwarnings("always", category=dccl.DcclValueChangedWarning, module=__name__)
        codec.encode(changed)
        assert len(record) == 1
        warnings.resetwarnings()
        warnings.simplefilter("ignore", dccl.DcclValueChangedWarning)
        warnings.filterwarnings("always", category=dccl.DcclValueChangedWarning, module="elsewhere")
        codec.encode(changed)
        assert len(record) == 1
        warnings.resetwarnings()
        warnings.simplefilter("error", dccl.DcclValueChangedWarning)
        with pytest.raises(dccl.DcclValueChangedWarning):
            codec.encode(changed)
    # The filters put back: warned again.
    with pytest.warns(dccl.DcclValueChangedWarning):
        codec.encode(changed)

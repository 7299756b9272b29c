// Answers encode and decode requests with the reference C++ library, libdccl
// 4.2 built with Lua (`-Denable_lua=ON`), for the dynamic-conditions test
// (`dccl/tests/dynamic_conditions.rs`), which compiles this file when
// DCCL_LUA_PREFIX names such a libdccl installation. Not part of the product;
// nothing else builds it.
//
// Usage: conditions_driver OUT_FILE -I DIR [-I DIR...] -f FILE.proto [-f ...]
//
// Reads one request a line on stdin, fields separated by tabs, and writes one
// answer a line to OUT_FILE (not to stdout: a condition may call Lua's
// `print`, which writes there):
//
//   L TYPE          -> ok HASH MIN_BYTES MAX_BYTES  |  err REASON
//   A TYPE          -> ok INFO (line breaks written as the byte 0x1f)
//   E TYPE TEXT     -> ok HEX DECODED STRICT  |  err REASON  |  perr REASON
//                      (DECODED: ShortDebugString of the bytes decoded, or
//                      !REASON; STRICT: the hex in strict mode, or !REASON)
//   D HEX           -> ok TYPE DECODED BYTES_USED  |  err REASON
//
// One codec answers every request in order, as a program embedding libdccl
// would use it.

#include <fstream>
#include <iostream>
#include <memory>
#include <sstream>
#include <string>
#include <vector>

#include <dccl/codec.h>
#include <dccl/dynamic_protobuf_manager.h>
#include <google/protobuf/text_format.h>

namespace
{
std::string to_hex(const std::string& bytes)
{
    static const char digits[] = "0123456789abcdef";
    std::string hex;
    for (unsigned char c : bytes)
    {
        hex.push_back(digits[c >> 4]);
        hex.push_back(digits[c & 0xf]);
    }
    return hex;
}

bool from_hex(const std::string& hex, std::string* out)
{
    if (hex.size() % 2)
        return false;
    out->clear();
    for (std::size_t i = 0; i < hex.size(); i += 2)
    {
        char* end = nullptr;
        std::string byte = hex.substr(i, 2);
        long v = std::strtol(byte.c_str(), &end, 16);
        if (*end)
            return false;
        out->push_back(static_cast<char>(v));
    }
    return true;
}

// One line: tabs and line breaks of a reason become spaces.
std::string flat(std::string s)
{
    for (char& c : s)
        if (c == '\n' || c == '\t' || c == '\r')
            c = ' ';
    return s;
}

std::shared_ptr<google::protobuf::Message> new_message(const std::string& type)
{
    return dccl::DynamicProtobufManager::new_protobuf_message<
        std::shared_ptr<google::protobuf::Message>>(type);
}

const google::protobuf::Descriptor* find_type(const std::string& type)
{
    return dccl::DynamicProtobufManager::find_descriptor(type);
}

std::string encode_line(dccl::Codec& codec, dccl::Codec& strict, const std::string& type,
                        const std::string& text)
{
    auto msg = new_message(type);
    if (!msg)
        return "err unknown type " + type;
    google::protobuf::TextFormat::Parser parser;
    parser.AllowPartialMessage(true);
    if (!parser.ParseFromString(text, msg.get()))
        return "perr cannot parse";
    std::string bytes;
    try
    {
        codec.encode(&bytes, *msg);
    }
    catch (std::exception& e)
    {
        return "err " + flat(e.what());
    }
    catch (...)
    {
        return "err (not a std::exception)";
    }
    std::string decoded;
    try
    {
        auto back = codec.decode<std::shared_ptr<google::protobuf::Message>>(bytes);
        decoded = back->ShortDebugString();
    }
    catch (std::exception& e)
    {
        decoded = "!" + flat(e.what());
    }
    catch (...)
    {
        decoded = "!(not a std::exception)";
    }
    std::string strict_hex;
    try
    {
        std::string strict_bytes;
        strict.encode(&strict_bytes, *msg);
        strict_hex = to_hex(strict_bytes);
    }
    catch (std::exception& e)
    {
        strict_hex = "!" + flat(e.what());
    }
    catch (...)
    {
        strict_hex = "!(not a std::exception)";
    }
    return "ok " + to_hex(bytes) + "\t" + decoded + "\t" + strict_hex;
}

std::string decode_line(dccl::Codec& codec, const std::string& hex)
{
    std::string bytes;
    if (!from_hex(hex, &bytes))
        return "err bad hex";
    try
    {
        std::string rest = bytes;
        auto msg = codec.decode<std::shared_ptr<google::protobuf::Message>>(&rest);
        return "ok " + msg->GetDescriptor()->full_name() + "\t" + msg->ShortDebugString() + "\t" +
               std::to_string(bytes.size() - rest.size());
    }
    catch (std::exception& e)
    {
        return "err " + flat(e.what());
    }
    catch (...)
    {
        return "err (not a std::exception)";
    }
}

std::string load_line(dccl::Codec& codec, dccl::Codec& strict, const std::string& type)
{
    const google::protobuf::Descriptor* desc = find_type(type);
    if (!desc)
        return "err unknown type " + type;
    try
    {
        std::size_t hash = codec.load(desc);
        strict.load(desc);
        std::stringstream ss;
        ss << "ok " << dccl::hash_as_string(hash) << " " << codec.min_size(desc) << " "
           << codec.max_size(desc);
        return ss.str();
    }
    catch (std::exception& e)
    {
        return "err " + flat(e.what());
    }
    catch (...)
    {
        return "err (not a std::exception)";
    }
}

std::string analyze_line(dccl::Codec& codec, const std::string& type)
{
    const google::protobuf::Descriptor* desc = find_type(type);
    if (!desc)
        return "err unknown type " + type;
    try
    {
        std::stringstream ss;
        codec.info(desc, &ss);
        std::string info = ss.str();
        for (char& c : info)
            if (c == '\n')
                c = '\x1f';
        return "ok " + info;
    }
    catch (std::exception& e)
    {
        return "err " + flat(e.what());
    }
}
} // namespace

int main(int argc, char** argv)
{
    if (argc < 2)
    {
        std::cerr << "usage: " << argv[0] << " OUT_FILE -I DIR... -f FILE.proto...\n";
        return 2;
    }
    std::ofstream out(argv[1]);
    if (!out)
    {
        std::cerr << "cannot write " << argv[1] << "\n";
        return 2;
    }
    std::vector<std::string> files;
    dccl::DynamicProtobufManager::enable_compilation();
    for (int i = 2; i + 1 < argc; i += 2)
    {
        std::string flag = argv[i];
        if (flag == "-I")
            dccl::DynamicProtobufManager::add_include_path(argv[i + 1]);
        else if (flag == "-f")
            files.push_back(argv[i + 1]);
        else
        {
            std::cerr << "unknown option " << flag << "\n";
            return 2;
        }
    }
    try
    {
        for (const auto& f : files) dccl::DynamicProtobufManager::load_from_proto_file(f);
    }
    catch (std::exception& e)
    {
        std::cerr << "cannot load: " << e.what() << "\n";
        return 1;
    }

    dccl::Codec codec;
    dccl::Codec strict;
    strict.set_strict(true);
    std::string line;
    while (std::getline(std::cin, line))
    {
        if (line.empty())
            continue;
        std::string::size_type tab = line.find('\t');
        std::string verb = line.substr(0, tab);
        std::string rest = tab == std::string::npos ? "" : line.substr(tab + 1);
        std::string answer;
        if (verb == "L")
            answer = load_line(codec, strict, rest);
        else if (verb == "A")
            answer = analyze_line(codec, rest);
        else if (verb == "E")
        {
            std::string::size_type t2 = rest.find('\t');
            answer = t2 == std::string::npos
                         ? "perr no text"
                         : encode_line(codec, strict, rest.substr(0, t2), rest.substr(t2 + 1));
        }
        else if (verb == "D")
            answer = decode_line(codec, rest);
        else
            answer = "err unknown request " + verb;
        out << answer << "\n";
        out.flush();
    }
    return 0;
}

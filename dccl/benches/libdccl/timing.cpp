// Times the reference C++ library, libdccl 4, on the shared DCCL vectors:
// the counterpart of the Rust timing in ../versus_libdccl.rs, which compiles
// this file when LIBDCCL_PREFIX names a libdccl installation and runs it
// between its own rounds. Not part of the product; nothing else builds it.
//
// Usage: timing INCLUDE_DIR VECTORS_DIR PASSES
//   INCLUDE_DIR  the libdccl prefix's include/ (holds dccl/option_extensions.proto)
//   VECTORS_DIR  holds vectors.proto and vectors.jsonl
//   PASSES       passes over the messages for each figure (the best pass counts)
//
// Prints one line:
//   libdccl VERSION messages N mismatches M encode_us E decode_us D
// E and D are microseconds per message of the fastest pass; M counts the
// vectors whose encoding differs from the reference bytes (`hex`).

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <iostream>
#include <memory>
#include <string>
#include <vector>

#include <dccl/codec.h>
#include <dccl/dynamic_protobuf_manager.h>
#include <dccl/version.h>
#include <google/protobuf/text_format.h>

namespace
{
// Appends the UTF-8 form of a code point.
void append_utf8(std::string* out, unsigned long cp)
{
    if (cp < 0x80)
        out->push_back(static_cast<char>(cp));
    else if (cp < 0x800)
    {
        out->push_back(static_cast<char>(0xc0 | (cp >> 6)));
        out->push_back(static_cast<char>(0x80 | (cp & 0x3f)));
    }
    else if (cp < 0x10000)
    {
        out->push_back(static_cast<char>(0xe0 | (cp >> 12)));
        out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3f)));
        out->push_back(static_cast<char>(0x80 | (cp & 0x3f)));
    }
    else
    {
        out->push_back(static_cast<char>(0xf0 | (cp >> 18)));
        out->push_back(static_cast<char>(0x80 | ((cp >> 12) & 0x3f)));
        out->push_back(static_cast<char>(0x80 | ((cp >> 6) & 0x3f)));
        out->push_back(static_cast<char>(0x80 | (cp & 0x3f)));
    }
}

// The string value of "key" in one line of JSON (the vectors' flat
// objects), escapes resolved; false when absent.
bool json_string(const std::string& line, const std::string& key, std::string* out)
{
    const std::string quoted = "\"" + key + "\"";
    std::string::size_type pos = line.find(quoted);
    if (pos == std::string::npos)
        return false;
    pos = line.find(':', pos + quoted.size());
    if (pos == std::string::npos)
        return false;
    pos = line.find('"', pos);
    if (pos == std::string::npos)
        return false;
    out->clear();
    for (++pos; pos < line.size(); ++pos)
    {
        char c = line[pos];
        if (c == '"')
            return true;
        if (c != '\\')
        {
            out->push_back(c);
            continue;
        }
        if (++pos >= line.size())
            return false;
        switch (line[pos])
        {
            case 'n': out->push_back('\n'); break;
            case 't': out->push_back('\t'); break;
            case 'r': out->push_back('\r'); break;
            case 'b': out->push_back('\b'); break;
            case 'f': out->push_back('\f'); break;
            case 'u':
            {
                if (pos + 4 >= line.size())
                    return false;
                unsigned long cp = std::strtoul(line.substr(pos + 1, 4).c_str(), nullptr, 16);
                pos += 4;
                if (cp >= 0xd800 && cp < 0xdc00 && pos + 6 < line.size() && line[pos + 1] == '\\' &&
                    line[pos + 2] == 'u')
                {
                    unsigned long low =
                        std::strtoul(line.substr(pos + 3, 4).c_str(), nullptr, 16);
                    cp = 0x10000 + ((cp - 0xd800) << 10) + (low - 0xdc00);
                    pos += 6;
                }
                append_utf8(out, cp);
                break;
            }
            default: out->push_back(line[pos]); break;
        }
    }
    return false;
}

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

double seconds_since(std::chrono::steady_clock::time_point start)
{
    return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}
} // namespace

int main(int argc, char** argv)
{
    if (argc != 4)
    {
        std::cerr << "usage: " << argv[0] << " INCLUDE_DIR VECTORS_DIR PASSES\n";
        return 2;
    }
    const std::string include_dir = argv[1];
    const std::string vectors_dir = argv[2];
    const int passes = std::atoi(argv[3]);
    if (passes < 1)
    {
        std::cerr << "PASSES must be at least 1\n";
        return 2;
    }

    try
    {
        dccl::DynamicProtobufManager::enable_compilation();
        dccl::DynamicProtobufManager::add_include_path(include_dir);
        dccl::DynamicProtobufManager::add_include_path(vectors_dir);
        dccl::DynamicProtobufManager::load_from_proto_file(vectors_dir + "/vectors.proto");

        dccl::Codec codec;
        std::vector<std::shared_ptr<google::protobuf::Message>> messages;
        std::vector<std::string> expected;
        std::vector<std::string> loaded;
        std::ifstream in(vectors_dir + "/vectors.jsonl");
        if (!in)
        {
            std::cerr << "cannot read " << vectors_dir << "/vectors.jsonl\n";
            return 1;
        }
        std::string line, name, input, hex;
        while (std::getline(in, line))
        {
            if (line.find_first_not_of(" \t\r") == std::string::npos)
                continue;
            if (!json_string(line, "message", &name) || !json_string(line, "input", &input) ||
                !json_string(line, "hex", &hex))
            {
                std::cerr << "vectors.jsonl: a line without message, input or hex\n";
                return 1;
            }
            auto msg = dccl::DynamicProtobufManager::new_protobuf_message<
                std::shared_ptr<google::protobuf::Message>>(name);
            google::protobuf::TextFormat::Parser parser;
            parser.AllowPartialMessage(true);
            if (!parser.ParseFromString(input, msg.get()))
            {
                std::cerr << "vectors.jsonl: cannot parse the input of a " << name << "\n";
                return 1;
            }
            bool known = false;
            for (const auto& l : loaded) known = known || l == name;
            if (!known)
            {
                codec.load(msg->GetDescriptor());
                loaded.push_back(name);
            }
            messages.push_back(msg);
            expected.push_back(hex);
        }
        if (messages.empty())
        {
            std::cerr << "vectors.jsonl holds no vector\n";
            return 1;
        }

        // Encoded once: the bytes to decode, and a check against the vectors.
        std::vector<std::string> encoded(messages.size());
        int mismatches = 0;
        for (std::size_t i = 0; i < messages.size(); ++i)
        {
            codec.encode(&encoded[i], *messages[i]);
            if (to_hex(encoded[i]) != expected[i])
                ++mismatches;
        }

        double best_encode = 1e300, best_decode = 1e300;
        std::string out;
        std::size_t sink = 0;
        for (int pass = 0; pass < passes; ++pass)
        {
            auto start = std::chrono::steady_clock::now();
            for (const auto& m : messages)
            {
                codec.encode(&out, *m);
                sink += out.size();
            }
            double t = seconds_since(start);
            if (t < best_encode)
                best_encode = t;
        }
        for (int pass = 0; pass < passes; ++pass)
        {
            auto start = std::chrono::steady_clock::now();
            for (const auto& bytes : encoded)
            {
                auto m = codec.decode<std::shared_ptr<google::protobuf::Message>>(bytes);
                sink += m != nullptr;
            }
            double t = seconds_since(start);
            if (t < best_decode)
                best_decode = t;
        }

        const double n = static_cast<double>(messages.size());
        std::printf("libdccl %d.%d messages %zu mismatches %d encode_us %.4f decode_us %.4f\n",
                    DCCL_VERSION_MAJOR, DCCL_VERSION_MINOR, messages.size(), mismatches,
                    best_encode / n * 1e6, best_decode / n * 1e6);
        if (sink == 0)
            std::fprintf(stderr, "(nothing encoded)\n");
    }
    catch (std::exception& e)
    {
        std::cerr << "libdccl: " << e.what() << "\n";
        return 1;
    }
    return 0;
}

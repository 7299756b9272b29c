// Times the reference C++ library, libdccl 4.2 built with Lua, on messages
// with dynamic conditions: the counterpart of the Rust timing in
// ../conditions_versus_libdccl.rs, which compiles this file when
// DCCL_LUA_PREFIX names such a libdccl installation and runs it between its
// own rounds. Not part of the product; nothing else builds it.
//
// Usage: conditions_timing INCLUDE_DIR DATA_DIR PASSES
//   INCLUDE_DIR  the libdccl prefix's include/ (holds dccl/option_extensions.proto)
//   DATA_DIR     holds conditions.proto, input.txt and expected.txt (as
//                dccl/tests/data/dynamic-conditions)
//   PASSES       passes over the messages for each figure (the best pass counts)
//
// The messages are the inputs that libdccl both encodes and decodes
// (`ok` in expected.txt, a decoded text not starting with `!`; the Rust
// side passes a copy of the directory holding the inputs it times). Prints one
// line (on the standard output it had when started: a condition's Lua
// `print` writes to the standard output, which is sent to /dev/null):
//   libdccl VERSION messages N mismatches M encode_us E decode_us D

#include <unistd.h>

#include <chrono>
#include <cstdio>
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

std::string from_hex(const std::string& hex)
{
    std::string out;
    for (std::size_t i = 0; i + 1 < hex.size(); i += 2)
        out.push_back(static_cast<char>(std::stoi(hex.substr(i, 2), nullptr, 16)));
    return out;
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
        std::cerr << "usage: " << argv[0] << " INCLUDE_DIR DATA_DIR PASSES\n";
        return 2;
    }
    const std::string include_dir = argv[1];
    const std::string data_dir = argv[2];
    const int passes = std::atoi(argv[3]);
    if (passes < 1)
    {
        std::cerr << "PASSES must be at least 1\n";
        return 2;
    }
    // The result goes to the standard output we were given; Lua's print to /dev/null.
    FILE* result = fdopen(dup(1), "w");
    if (!result || !std::freopen("/dev/null", "w", stdout))
    {
        std::cerr << "cannot set up the standard output\n";
        return 1;
    }

    try
    {
        dccl::DynamicProtobufManager::enable_compilation();
        dccl::DynamicProtobufManager::add_include_path(include_dir);
        dccl::DynamicProtobufManager::add_include_path(data_dir);
        dccl::DynamicProtobufManager::load_from_proto_file("conditions.proto");

        dccl::Codec codec;
        std::vector<std::shared_ptr<google::protobuf::Message>> messages;
        std::vector<std::string> expected;
        std::vector<std::string> loaded;
        std::ifstream inputs(data_dir + "/input.txt"), answers(data_dir + "/expected.txt");
        std::string input, answer;
        while (std::getline(inputs, input) && std::getline(answers, answer))
        {
            if (answer.rfind("ok ", 0) != 0)
                continue;
            std::string::size_type tab = answer.find('\t');
            if (tab == std::string::npos || answer.compare(tab + 1, 1, "!") == 0)
                continue;
            std::string::size_type bar = input.find('|', 1);
            std::string name = input.substr(1, bar - 1);
            std::string text = input.substr(bar + 1);
            auto msg = dccl::DynamicProtobufManager::new_protobuf_message<
                std::shared_ptr<google::protobuf::Message>>(name);
            google::protobuf::TextFormat::Parser parser;
            parser.AllowPartialMessage(true);
            if (!parser.ParseFromString(text, msg.get()))
                continue;
            bool known = false;
            for (const auto& l : loaded) known = known || l == name;
            if (!known)
            {
                codec.load(msg->GetDescriptor());
                loaded.push_back(name);
            }
            messages.push_back(msg);
            expected.push_back(answer.substr(3, tab - 3));
        }
        if (messages.empty())
        {
            std::cerr << "no message to time in " << data_dir << "\n";
            return 1;
        }

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
        std::fprintf(result,
                     "libdccl %d.%d messages %zu mismatches %d encode_us %.4f decode_us %.4f\n",
                     DCCL_VERSION_MAJOR, DCCL_VERSION_MINOR, messages.size(), mismatches,
                     best_encode / n * 1e6, best_decode / n * 1e6);
        std::fflush(result);
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

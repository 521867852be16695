#include "server/Log.h"

#include <chrono>
#include <cstdio>
#include <ctime>
#include <string>

namespace bc::server {

namespace {

/// `line` with control characters escaped (\n, \xNN): text a client sent (an Error's message)
/// reaches the log, and must not start a line of its own there.
std::string printable(const std::string& line) {
    std::string out;
    out.reserve(line.size());
    for (const char c : line) {
        const auto u = static_cast<unsigned char>(c);
        if (c == '\n') {
            out += "\\n";
        } else if (u < 0x20 || u == 0x7f) {
            char hex[8];
            std::snprintf(hex, sizeof hex, "\\x%02x", u);
            out += hex;
        } else {
            out += c;
        }
    }
    return out;
}

} // namespace

void Log::info(const std::string& line) {
    if (!mQuiet) write("info", line);
}

void Log::error(const std::string& line) {
    write("error", line);
}

void Log::write(const char* level, const std::string& line) {
    const auto now = std::chrono::system_clock::now();
    const std::time_t seconds = std::chrono::system_clock::to_time_t(now);
    const auto ms =
        std::chrono::duration_cast<std::chrono::milliseconds>(now.time_since_epoch()) % 1000;
    std::tm utc{};
    gmtime_r(&seconds, &utc);
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%dT%H:%M:%S", &utc);
    std::lock_guard lock(mMutex);
    std::fprintf(stderr, "%s.%03dZ %s %s\n", stamp, int(ms.count()), level,
                 printable(line).c_str());
    std::fflush(stderr);
}

} // namespace bc::server

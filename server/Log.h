#pragma once
// The daemon's log: one line per event on stderr ("2026-12-01T18:00:00.123Z info session 3
// from 127.0.0.1:40112 started"). Thread-safe; lines never interleave.
#include <mutex>
#include <string>

namespace bc::server {

class Log {
  public:
    /// `quiet` drops info lines (tests); errors are always written.
    explicit Log(bool quiet = false) : mQuiet(quiet) {}
    void info(const std::string& line);
    void error(const std::string& line);

  private:
    void write(const char* level, const std::string& line);
    bool mQuiet;
    std::mutex mMutex;
};

} // namespace bc::server

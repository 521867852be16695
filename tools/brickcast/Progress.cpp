#include "tools/brickcast/Progress.h"

#include <cstdio>
#include <unistd.h>

namespace bc::cli {

ProgressLine::ProgressLine(bool enabled) : mActive(enabled && ::isatty(STDERR_FILENO)) {}

void ProgressLine::update(const brickstore::IngestProgress& p) {
    if (!mActive) return;
    auto now = std::chrono::steady_clock::now();
    if (now - mLastDraw < std::chrono::milliseconds(200)) return;
    mLastDraw = now;
    double mbps = p.seconds > 0 ? double(p.sourceBytesRead) / 1e6 / p.seconds : 0.0;
    double done = p.sourceBytesTotal ? double(p.sourceBytesRead) / double(p.sourceBytesTotal) : 0.0;
    double left = done > 0 ? p.seconds * (1.0 - done) / done : 0.0;
    std::fprintf(stderr,
                 "\r  %.1f / %.1f MB read  %5.1f%%  %7.1f MB/s  %5.0f s left  bricks %llu/%llu ",
                 double(p.sourceBytesRead) / 1e6, double(p.sourceBytesTotal) / 1e6, 100.0 * done,
                 mbps, left, (unsigned long long)p.bricksDone, (unsigned long long)p.bricksTotal);
    std::fflush(stderr);
}

void ProgressLine::finish() {
    if (!mActive) return;
    std::fprintf(stderr, "\r%78s\r", "");
    std::fflush(stderr);
}

} // namespace bc::cli

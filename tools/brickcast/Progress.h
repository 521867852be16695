#pragma once
// A progress line for long ingests, redrawn in place on a terminal and silent in logs and pipes.
#include "brickstore/Ingest.h"

#include <chrono>

namespace bc::cli {

class ProgressLine {
  public:
    /// Shows progress only when `enabled` and stderr is a terminal.
    explicit ProgressLine(bool enabled);
    void update(const brickstore::IngestProgress& p);
    /// Clears the line.
    void finish();

  private:
    bool mActive;
    std::chrono::steady_clock::time_point mLastDraw{};
};

} // namespace bc::cli

#pragma once
// The rows of bc_bench_render and their three outputs: a markdown table, CSV, and a PNG
// plot of run time against error drawn by gnuplot.
#include <cmath>
#include <cstdint>
#include <string>
#include <vector>

namespace bc::bench {

struct BenchRow {
    std::string kind = "path"; ///< "path" (technique sets) or "sweep" (steps, all techniques)
    std::string dataset, tf, path, technique;
    std::uint32_t size = 0;
    double step = 1.0;
    double ms = 0, spp = 0;
    double overOracle = std::nan(""), psnr = std::nan(""),
           ssim = std::nan(""); ///< NaN: no reference
    double octreeRebuildMs = 0, frustumBuildMs = 0, frustumTriangles = 0;
    double cellBuildMs = 0; ///< distance maps built by the path's first frame (summed over threads)
    int frustumFrames = 0;
};

class BenchReport {
  public:
    void add(BenchRow row) { mRows.push_back(std::move(row)); }
    /// Technique rows with their speed-up over the plain row of the same scene, then sweeps.
    void printMarkdown() const;
    /// @throw std::runtime_error naming the file when it cannot be written.
    void writeCsv(const std::string& path) const;
    /// Runs gnuplot on data files written under `scratch`. @throw std::runtime_error when
    /// gnuplot is missing or fails.
    void writePlot(const std::string& path, const std::string& scratch);

  private:
    double plainMs(const BenchRow& row) const;
    std::vector<BenchRow> mRows;
    std::vector<std::string> mTechniques; ///< technique sets in plot order
};

} // namespace bc::bench

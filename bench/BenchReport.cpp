#include "bench/BenchReport.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <stdexcept>

namespace bc::bench {
namespace {

std::string psnrText(double psnr) {
    if (std::isinf(psnr)) return "inf";
    if (std::isnan(psnr)) return "n/a";
    char b[32];
    std::snprintf(b, sizeof b, "%.1f", psnr);
    return b;
}

/// gnuplot reads "inf" badly: the plot caps PSNR at 150 dB.
double plotted(double psnr) {
    return std::isfinite(psnr) ? std::min(psnr, 150.0) : 150.0;
}

std::string ssimText(double ssim) {
    if (std::isnan(ssim)) return "n/a";
    char b[32];
    std::snprintf(b, sizeof b, "%.4f", ssim);
    return b;
}

} // namespace

double BenchReport::plainMs(const BenchRow& row) const {
    for (const auto& r : mRows)
        if (r.kind == "path" && r.technique.starts_with("plain") &&
            r.technique.ends_with(" (CPU)") == row.technique.ends_with(" (CPU)") &&
            r.dataset == row.dataset && r.tf == row.tf && r.path == row.path && r.size == row.size)
            return r.ms;
    return 0.0;
}

void BenchReport::printMarkdown() const {
    std::printf("\n| dataset / TF | path | size | technique | ms/frame | speed-up | samples/px | "
                "samples/oracle | PSNR dB | SSIM | octree ms | cell maps ms | frustum ms | "
                "triangles | frustum frames |\n"
                "|---|---|---:|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n");
    for (const auto& r : mRows) {
        if (r.kind != "path") continue;
        const double plain = plainMs(r);
        std::printf("| %s / %s | %s | %u | %s | %.1f | %.2fx | %.1f | %.2f | %s | %s | %.2f | "
                    "%.2f | %.2f | %.0f | %d |\n",
                    r.dataset.c_str(), r.tf.c_str(), r.path.c_str(), r.size, r.technique.c_str(),
                    r.ms, plain > 0 ? plain / r.ms : 0.0, r.spp, r.overOracle,
                    psnrText(r.psnr).c_str(), ssimText(r.ssim).c_str(), r.octreeRebuildMs,
                    r.cellBuildMs, r.frustumBuildMs, r.frustumTriangles, r.frustumFrames);
    }
    std::printf("\nRun time against error (all techniques, orbit; error against the CPU reference "
                "at the finest step)\n\n| dataset / TF | size | step | ms/frame | samples/px | "
                "PSNR dB | SSIM |\n|---|---:|---:|---:|---:|---:|---:|\n");
    for (const auto& r : mRows)
        if (r.kind == "sweep")
            std::printf("| %s / %s | %u | %.2f | %.1f | %.1f | %s | %s |\n", r.dataset.c_str(),
                        r.tf.c_str(), r.size, r.step, r.ms, r.spp, psnrText(r.psnr).c_str(),
                        ssimText(r.ssim).c_str());
}

void BenchReport::writeCsv(const std::string& path) const {
    std::ofstream f(path);
    f << "kind,dataset,tf,path,size,technique,step,ms,speedup,samples_per_pixel,samples_over_"
         "oracle,"
         "psnr_db,ssim,octree_rebuild_ms,cell_build_ms,frustum_build_ms,frustum_triangles,"
         "frustum_frames\n";
    for (const auto& r : mRows) {
        const double plain = r.kind == "path" ? plainMs(r) : 0.0;
        f << r.kind << ',' << r.dataset << ',' << r.tf << ',' << r.path << ',' << r.size << ','
          << r.technique << ',' << r.step << ',' << r.ms << ',' << (plain > 0 ? plain / r.ms : 0)
          << ',' << r.spp << ',' << r.overOracle << ',' << psnrText(r.psnr) << ','
          << ssimText(r.ssim) << ',' << r.octreeRebuildMs << ',' << r.cellBuildMs << ','
          << r.frustumBuildMs << ',' << r.frustumTriangles << ',' << r.frustumFrames << '\n';
    }
    if (!f) throw std::runtime_error(path + ": cannot write the CSV");
}

void BenchReport::writePlot(const std::string& path, const std::string& scratch) {
    // One data file per scene: the step sweep as a line, the technique sets as points.
    std::map<std::string, std::pair<std::string, std::string>> files;
    for (const auto& r : mRows) {
        if ((r.kind == "path" && r.path != "orbit") || std::isnan(r.psnr)) continue;
        const std::string scene = r.dataset + " / " + r.tf;
        auto& [sweep, sets] = files[scene];
        if (sweep.empty()) {
            const std::string base = scratch + "/plot" + std::to_string(files.size());
            sweep = base + "-sweep.dat";
            sets = base + "-sets.dat";
            std::ofstream(sweep).close();
            std::ofstream(sets).close();
        }
        std::ofstream out(r.kind == "sweep" ? sweep : sets, std::ios::app);
        std::size_t kind = 0; // gnuplot point type of the technique set
        for (; kind < mTechniques.size() && mTechniques[kind] != r.technique; ++kind) {
        }
        if (kind == mTechniques.size()) mTechniques.push_back(r.technique);
        out << r.ms << ' ' << plotted(r.psnr) << ' ' << kind + 4 << '\n';
    }
    const std::string script = scratch + "/plot.gp";
    {
        std::ofstream g(script);
        g << "set terminal png size 1200,800 noenhanced\nset output '" << path << "'\n"
          << "set title 'Run time against error (orbit, first size; PSNR against the CPU "
             "reference, capped at 150 dB)'\n"
          << "set xlabel 'ms/frame (log)'\nset ylabel 'PSNR dB'\nset logscale x\n"
          << "set key outside right\nset grid\nplot ";
        int i = 0;
        for (const auto& [scene, f] : files) {
            g << (i ? ", \\\n  " : "") << "'" << f.first << "' using 1:2 with linespoints lw 2 lc "
              << i + 1 << " title '" << scene << " (step sweep)', '" << f.second
              << "' using 1:2:3 with points pt variable ps 2 lc " << i + 1 << " notitle";
            ++i;
        }
        for (std::size_t k = 0; k < mTechniques.size(); ++k) // a key for the point types
            g << ", \\\n  NaN with points pt " << k + 4 << " ps 2 lc rgb 'black' title '"
              << mTechniques[k] << "'";
        g << "\n";
    }
    const std::string command = "gnuplot '" + script + "'";
    if (std::system(command.c_str()) != 0)
        throw std::runtime_error(
            "--plot: gnuplot failed or is missing (apt-get install gnuplot-nox)");
}

} // namespace bc::bench

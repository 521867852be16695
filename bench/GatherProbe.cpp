// Gather probe: what one vector gather costs on this machine, against plain loads of
// the same elements, for the two gathers the CPU raycaster's march is made of
// (render/detail/CpuMarchSimd.cpp): 32-bit lanes (a 16-bit voxel pair, an octree word, a TF
// entry) and 64-bit lanes (a 32-bit voxel pair, a TF pair), from a 68^3-float brick in cache at
// offsets of one 4x4 packet's neighbouring cells. A step of the march takes 4 to 11 of them,
// so their cost per element is the floor under its time per sample.
//
//   bc_bench_gathers [--reps N]   # prints the target, ns per gather and per element loaded
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "bench/GatherProbe.cpp"
#include <hwy/foreach_target.h> // IWYU pragma: keep

#include <hwy/highway.h>

#include <algorithm>
#include <chrono>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <vector>

#ifndef BC_GATHER_PROBE_TYPES
#define BC_GATHER_PROBE_TYPES
namespace bc::bench {

constexpr int kEdge = 68;
constexpr int kMask = (1 << 17) - 1; ///< offsets wrap inside the brick (68^3 > 2^18)

/// Nanoseconds per iteration of `n` iterations of f, best of `reps` runs.
template <class F> double bestNs(int reps, long n, F&& f) {
    double best = 1e30;
    for (int r = 0; r < reps; ++r) {
        const auto t = std::chrono::steady_clock::now();
        f(n);
        const double ns =
            std::chrono::duration<double, std::nano>(std::chrono::steady_clock::now() - t).count();
        best = std::min(best, ns / double(n));
    }
    return best;
}

struct Result {
    const char* target;
    int lanes;
    double gather32, gather64, scalar32; ///< ns per vector of lanes (gather64: lanes / 2)
    float sink;
};

} // namespace bc::bench
#endif

HWY_BEFORE_NAMESPACE();
namespace bc::bench {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;

Result Probe(const float* brick, int reps) {
    const hn::ScalableTag<float> df;
    const hn::RebindToSigned<decltype(df)> di;
    const hn::Repartition<std::int64_t, decltype(df)> d64;
    const int lanes = int(hn::Lanes(df));
    // A 4x4 packet's cells: four rows of four neighbouring x positions, as the march reads.
    std::vector<std::int32_t> cell(std::size_t(hn::MaxLanes(df)));
    for (int i = 0; i < lanes; ++i)
        cell[std::size_t(i)] = (i / 4) * kEdge + (i % 4);
    const auto base = hn::LoadU(di, cell.data());
    const auto mask = hn::Set(di, kMask);
    const auto stride = hn::Set(di, 4625); // moves through the brick, one cell to the next
    const long n = 2000000;
    Result out{hwy::TargetName(HWY_TARGET), lanes, 0, 0, 0, 0};
    {
        auto acc = hn::Zero(df);
        out.gather32 = bestNs(reps, n, [&](long m) {
            auto off = hn::Zero(di);
            for (long i = 0; i < m; ++i) {
                acc = hn::Add(acc, hn::GatherIndex(df, brick, hn::Add(base, off)));
                off = hn::And(hn::Add(off, stride), mask);
            }
        });
        out.sink += hn::GetLane(acc);
    }
    {
        auto acc = hn::Zero(d64);
        const hn::Half<decltype(di)> dh;
        const auto* words = reinterpret_cast<const std::int64_t*>(brick);
        out.gather64 = bestNs(reps, n, [&](long m) {
            auto off = hn::Zero(di);
            for (long i = 0; i < m; ++i) {
                const auto bytes = hn::ShiftLeft<2>(hn::Add(base, off));
                acc = hn::Add(acc, hn::GatherOffset(d64, words,
                                                    hn::PromoteTo(d64, hn::LowerHalf(dh, bytes))));
                off = hn::And(hn::Add(off, stride), mask);
            }
        });
        out.sink += float(hn::GetLane(acc) & 1);
    }
    {
        // Four sums, so that the adds' latency does not hide the loads' throughput.
        // Four integer sums (one-cycle adds), so that the loads, not the adds, are timed.
        std::uint32_t sum = 0;
        const std::int32_t* at = cell.data();
        auto word = [&](std::int32_t i) {
            std::uint32_t w;
            std::memcpy(&w, brick + i, sizeof w);
            return w;
        };
        out.scalar32 = bestNs(reps, n, [&](long m) {
            std::uint32_t a0 = 0, a1 = 0, a2 = 0, a3 = 0;
            std::int32_t off = 0;
            for (long i = 0; i < m; ++i) {
                for (int j = 0; j + 3 < lanes; j += 4) {
                    a0 += word(at[j] + off);
                    a1 += word(at[j + 1] + off);
                    a2 += word(at[j + 2] + off);
                    a3 += word(at[j + 3] + off);
                }
                off = (off + 4625) & kMask;
            }
            sum += a0 ^ a1 ^ a2 ^ a3;
        });
        out.sink += float(sum & 1u);
    }
    return out;
}

} // namespace HWY_NAMESPACE
} // namespace bc::bench
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace bc::bench {
HWY_EXPORT(Probe);
} // namespace bc::bench

int main(int argc, char** argv) {
    int reps = 5;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--reps" && i + 1 < argc) {
            reps = std::max(1, std::atoi(argv[++i]));
        } else {
            std::fprintf(stderr, "usage: bc_bench_gathers [--reps N]\n");
            return 2;
        }
    }
    using namespace bc::bench;
    std::vector<float> brick(std::size_t(kEdge) * kEdge * kEdge + 4 * kEdge, 1.0f);
    const Result r = HWY_DYNAMIC_DISPATCH(Probe)(brick.data(), reps);
    std::printf("target %s, %d lanes of 32 bits; a 68^3-float brick in cache, best of %d runs\n",
                r.target, r.lanes, reps);
    std::printf(
        "| load | ns per instruction | elements | ns per element |\n|---|---:|---:|---:|\n");
    std::printf("| gather, 32-bit lanes | %.2f | %d | %.3f |\n", r.gather32, r.lanes,
                r.gather32 / r.lanes);
    std::printf("| gather, 64-bit lanes | %.2f | %d | %.3f |\n", r.gather64, r.lanes / 2,
                r.gather64 / (r.lanes / 2));
    std::printf("| scalar loads (per vector's worth) | %.2f | %d | %.3f |\n", r.scalar32, r.lanes,
                r.scalar32 / r.lanes);
    std::fflush(stdout);
    return r.sink == 12345.0f ? 1 : 0; // keeps the loads
}
#endif

// Packet probe: what marching 16 rays per vector (one sample per lane per step)
// would gain over the CPU raycaster's layout (16 consecutive samples of one ray per vector,
// composited lane by lane), measured on a real scan with the same sample work in both: trilinear
// u16, a 4096-entry TF, central-difference gradient and Blinn-Phong, early termination, and
// optionally 8-voxel leaf skipping (a lane in an empty leaf leaps to the leaf's exit while the
// others sample). Both kernels do the same float operations per sample, so their images agree
// to the bit; the probe checks that and prints times and the ratio. A flat padded volume and an
// orthographic camera, no bricks: a model of the march, not the renderer (render/CpuRaycaster).
//
//   bc_bench_packets --tf bone --skip      # cthead from ../shared/data, 256^2, 7 repetitions
#undef HWY_TARGET_INCLUDE
#define HWY_TARGET_INCLUDE "bench/PacketProbe.cpp"
#include <hwy/foreach_target.h> // IWYU pragma: keep

#include <hwy/highway.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#ifndef BC_PACKET_PROBE_TYPES
#define BC_PACKET_PROBE_TYPES
namespace bc::bench {

struct Vol {
    int nx, ny, nz, px, py, pz; // padded dims
    std::vector<uint16_t> v;    // padded by 2
    int sy, sz;
};

struct Leaves {
    int lx, ly, lz;           // leaves per axis (8-voxel leaves over the padded volume)
    std::vector<int32_t> occ; // 1: some sample in the leaf may be visible
};

struct Tf {
    std::vector<float> rgba; // 4096 x 4
    float scale;
};

struct Ray {
    float ox, oy, oz, dx, dy, dz, t0;
    int total;
};

struct Acc {
    float r = 0, g = 0, b = 0, t = 1;
};

constexpr float kErtT = 0.01f;

} // namespace bc::bench
#endif

HWY_BEFORE_NAMESPACE();
namespace bc::bench {
namespace HWY_NAMESPACE {
namespace hn = hwy::HWY_NAMESPACE;
using DF = hn::ScalableTag<float>;
using DI = hn::RebindToSigned<DF>;
using VF = hn::Vec<DF>;
using VI = hn::Vec<DI>;

HWY_INLINE VF lerpV(VF a, VF b, VF t) {
    const VF one = hn::Set(DF(), 1.0f);
    return hn::Add(hn::Mul(a, hn::Sub(one, t)), hn::Mul(b, t));
}

struct PairF {
    VF lo, hi;
};
HWY_INLINE PairF pairAt(const uint16_t* v, VI o) {
    const DF df;
    const DI di;
    const VI w = hn::GatherOffset(di, reinterpret_cast<const int32_t*>(v), hn::ShiftLeft<1>(o));
    const VI half = hn::Set(di, 0xFFFF);
    return {hn::ConvertTo(df, hn::And(w, half)), hn::ConvertTo(df, hn::ShiftRight<16>(w))};
}

// One vector of samples at positions (qx, qy, qz) (voxel coords of the padded volume, >= 1):
// rgba out; returns false when no lane is visible.
HWY_INLINE bool sampleV(const Vol& V, const Tf& T, VF qx, VF qy, VF qz, float ldx, float ldy,
                        float ldz, VF& r, VF& g, VF& b, VF& a) {
    const DF df;
    const DI di;
    const VI x0 = hn::ConvertTo(di, qx), y0 = hn::ConvertTo(di, qy), z0 = hn::ConvertTo(di, qz);
    const VF fx = hn::Sub(qx, hn::ConvertTo(df, x0)), fy = hn::Sub(qy, hn::ConvertTo(df, y0)),
             fz = hn::Sub(qz, hn::ConvertTo(df, z0));
    const VI sy = hn::Set(di, V.sy), sz = hn::Set(di, V.sz);
    const VI o = hn::Add(hn::Add(hn::Mul(z0, sz), hn::Mul(y0, sy)), x0);
    const uint16_t* v = V.v.data();
    const VI o10 = hn::Add(o, sy), o01 = hn::Add(o, sz), o11 = hn::Add(o10, sz);
    const PairF r00 = pairAt(v, o), r10 = pairAt(v, o10), r01 = pairAt(v, o01),
                r11 = pairAt(v, o11);
    const VF value = lerpV(lerpV(lerpV(r00.lo, r00.hi, fx), lerpV(r10.lo, r10.hi, fx), fy),
                           lerpV(lerpV(r01.lo, r01.hi, fx), lerpV(r11.lo, r11.hi, fx), fy), fz);
    const VF u =
        hn::Min(hn::Max(hn::Mul(value, hn::Set(df, T.scale)), hn::Zero(df)), hn::Set(df, 4095.0f));
    const VI entry = hn::Min(hn::ConvertTo(di, u), hn::Set(di, 4094));
    const VF w = hn::Sub(u, hn::ConvertTo(df, entry));
    const VI e = hn::ShiftLeft<2>(entry);
    auto channel = [&](int ch) {
        return lerpV(hn::GatherIndex(df, T.rgba.data(), hn::Add(e, hn::Set(di, ch))),
                     hn::GatherIndex(df, T.rgba.data(), hn::Add(e, hn::Set(di, ch + 4))), w);
    };
    a = channel(3);
    if (hn::AllFalse(df, hn::Gt(a, hn::Zero(df)))) return false;
    r = channel(0);
    g = channel(1);
    b = channel(2);
    // gradient: x from outer pairs, y and z from neighbour rows
    const VI one = hn::Set(di, 1);
    auto outer = [&](VI oo) {
        return PairF{pairAt(v, hn::Sub(oo, one)).lo, pairAt(v, hn::Add(oo, one)).hi};
    };
    const PairF x00 = outer(o), x10 = outer(o10), x01 = outer(o01), x11 = outer(o11);
    auto tri = [&](VF d000, VF d100, VF d010, VF d110, VF d001, VF d101, VF d011, VF d111) {
        return lerpV(lerpV(lerpV(d000, d100, fx), lerpV(d010, d110, fx), fy),
                     lerpV(lerpV(d001, d101, fx), lerpV(d011, d111, fx), fy), fz);
    };
    const VF gx = tri(hn::Sub(r00.hi, x00.lo), hn::Sub(x00.hi, r00.lo), hn::Sub(r10.hi, x10.lo),
                      hn::Sub(x10.hi, r10.lo), hn::Sub(r01.hi, x01.lo), hn::Sub(x01.hi, r01.lo),
                      hn::Sub(r11.hi, x11.lo), hn::Sub(x11.hi, r11.lo));
    const VI sy2 = hn::Add(sy, sy), sz2 = hn::Add(sz, sz);
    const PairF ym0 = pairAt(v, hn::Sub(o, sy)), yp0 = pairAt(v, hn::Add(o, sy2));
    const PairF ym1 = pairAt(v, hn::Sub(o01, sy)), yp1 = pairAt(v, hn::Add(o01, sy2));
    const VF gy = tri(hn::Sub(r10.lo, ym0.lo), hn::Sub(r10.hi, ym0.hi), hn::Sub(yp0.lo, r00.lo),
                      hn::Sub(yp0.hi, r00.hi), hn::Sub(r11.lo, ym1.lo), hn::Sub(r11.hi, ym1.hi),
                      hn::Sub(yp1.lo, r01.lo), hn::Sub(yp1.hi, r01.hi));
    const PairF zm0 = pairAt(v, hn::Sub(o, sz)), zp0 = pairAt(v, hn::Add(o, sz2));
    const PairF zm1 = pairAt(v, hn::Sub(o10, sz)), zp1 = pairAt(v, hn::Add(o10, sz2));
    const VF gz = tri(hn::Sub(r01.lo, zm0.lo), hn::Sub(r01.hi, zm0.hi), hn::Sub(r11.lo, zm1.lo),
                      hn::Sub(r11.hi, zm1.hi), hn::Sub(zp0.lo, r00.lo), hn::Sub(zp0.hi, r00.hi),
                      hn::Sub(zp1.lo, r10.lo), hn::Sub(zp1.hi, r10.hi));
    const VF len = hn::Sqrt(hn::Add(hn::Add(hn::Mul(gx, gx), hn::Mul(gy, gy)), hn::Mul(gz, gz)));
    const auto lit = hn::Gt(len, hn::Zero(df));
    const VF diff = hn::Abs(hn::Add(hn::Add(hn::Mul(hn::Div(gx, len), hn::Set(df, ldx)),
                                            hn::Mul(hn::Div(gy, len), hn::Set(df, ldy))),
                                    hn::Mul(hn::Div(gz, len), hn::Set(df, ldz))));
    const VF x3 = hn::Mul(hn::Mul(diff, diff), diff), x6 = hn::Mul(x3, x3), x12 = hn::Mul(x6, x6);
    const VF spec = hn::Mul(hn::Set(df, 0.25f), hn::Mul(x12, x12));
    const VF k = hn::Add(hn::Set(df, 0.3f), hn::Mul(hn::Set(df, 0.7f), diff));
    const VF wf =
        hn::Min(hn::Max(hn::Div(len, hn::Set(df, 40.0f)), hn::Zero(df)), hn::Set(df, 1.0f));
    auto apply = [&](VF x) {
        return hn::IfThenElse(lit,
                              hn::Add(x, hn::Mul(hn::Sub(hn::Add(hn::Mul(x, k), spec), x), wf)), x);
    };
    r = apply(r);
    g = apply(g);
    b = apply(b);
    return true;
}

// The first of samples [k, k + count) whose leaf is occupied (-1: none); leafOut: the leaf of
// the last sample.
HWY_INLINE int firstOccupied(const Leaves& L, const Ray& ray, float step, int k, int count,
                             int* leafOut) {
    const DF df;
    const DI di;
    const VI index = hn::Min(hn::Add(hn::Set(di, k), hn::Iota(di, 0)), hn::Set(di, k + count - 1));
    const VF t =
        hn::Add(hn::Set(df, ray.t0),
                hn::Mul(hn::Add(hn::ConvertTo(df, index), hn::Set(df, 0.5f)), hn::Set(df, step)));
    const VF inv = hn::Set(df, 0.125f);
    const VI lx = hn::ConvertTo(
        di, hn::Mul(hn::Add(hn::Set(df, ray.ox), hn::Mul(hn::Set(df, ray.dx), t)), inv));
    const VI ly = hn::ConvertTo(
        di, hn::Mul(hn::Add(hn::Set(df, ray.oy), hn::Mul(hn::Set(df, ray.dy), t)), inv));
    const VI lz = hn::ConvertTo(
        di, hn::Mul(hn::Add(hn::Set(df, ray.oz), hn::Mul(hn::Set(df, ray.dz), t)), inv));
    const VI idx =
        hn::Add(hn::Mul(hn::Add(hn::Mul(lz, hn::Set(di, L.ly)), ly), hn::Set(di, L.lx)), lx);
    const VI occ = hn::GatherIndex(di, L.occ.data(), idx);
    const int first = int(
        hn::FindFirstTrue(di, hn::And(hn::Ne(occ, hn::Zero(di)), hn::FirstN(di, size_t(count)))));
    if (first < 0) {
        leafOut[0] = hn::ExtractLane(lx, size_t(count - 1));
        leafOut[1] = hn::ExtractLane(ly, size_t(count - 1));
        leafOut[2] = hn::ExtractLane(lz, size_t(count - 1));
    }
    return first;
}

// The first sample at or after the exit of leaf `leaf` (8-voxel cube).
HWY_INLINE int afterLeaf(const Ray& ray, float step, const int* leaf) {
    const float o[3] = {ray.ox, ray.oy, ray.oz}, d[3] = {ray.dx, ray.dy, ray.dz};
    float te = 3e38f;
    for (int a = 0; a < 3; ++a)
        if (d[a] != 0.0f)
            te = std::min(te, (float(leaf[a] * 8 + (d[a] > 0 ? 8 : 0)) - o[a]) / d[a]);
    return int(std::ceil((te - ray.t0) / step - 0.5f));
}

// A, today's layout: per ray, 16 consecutive samples per vector, composited lane by lane;
// with leaves (L not null), a vector wholly in empty leaves leaps past the last one's leaf and a
// vector starts at its first sample in an occupied leaf.
void marchChunks(const Vol& V, const Tf& T, const Leaves* L, const Ray& ray, float step, Acc& acc,
                 uint64_t& n) {
    const DF df;
    const DI di;
    const int lanes = int(hn::Lanes(df));
    HWY_ALIGN float rs[64], gs[64], bs[64], as[64];
    for (int k = 0; k < ray.total;) {
        int count = std::min(lanes, ray.total - k);
        int leaf[3];
        const int first = L ? firstOccupied(*L, ray, step, k, count, leaf) : 0;
        if (first < 0) {
            k = std::max(k + count, std::min(afterLeaf(ray, step, leaf), ray.total));
            continue;
        }
        k += first;
        count = std::min(lanes, ray.total - k);
        const VI index =
            hn::Min(hn::Add(hn::Set(di, k), hn::Iota(di, 0)), hn::Set(di, k + count - 1));
        const VF t = hn::Add(
            hn::Set(df, ray.t0),
            hn::Mul(hn::Add(hn::ConvertTo(df, index), hn::Set(df, 0.5f)), hn::Set(df, step)));
        const VF qx = hn::Add(hn::Set(df, ray.ox), hn::Mul(hn::Set(df, ray.dx), t));
        const VF qy = hn::Add(hn::Set(df, ray.oy), hn::Mul(hn::Set(df, ray.dy), t));
        const VF qz = hn::Add(hn::Set(df, ray.oz), hn::Mul(hn::Set(df, ray.dz), t));
        VF r, g, b, a;
        const bool vis = sampleV(V, T, qx, qy, qz, ray.dx, ray.dy, ray.dz, r, g, b, a);
        if (!vis) {
            n += uint64_t(count);
            k += count;
            continue;
        }
        hn::Store(r, df, rs);
        hn::Store(g, df, gs);
        hn::Store(b, df, bs);
        hn::Store(a, df, as);
        Acc s = acc;
        for (int j = 0; j < count; ++j) {
            const float w = s.t * as[j];
            s.r += w * rs[j];
            s.g += w * gs[j];
            s.b += w * bs[j];
            s.t *= 1.0f - as[j];
            if (s.t <= kErtT) {
                acc = s;
                n += uint64_t(j + 1);
                return;
            }
        }
        acc = s;
        n += uint64_t(count);
        k += count;
    }
}

// B, packets: Lanes() rays, one sample per lane per step, a vector composite; with leaves (L
// not null) a lane in an empty leaf leaps to the leaf's exit while the others sample.
void marchPacket(const Vol& V, const Tf& T, const Leaves* L, const Ray* rays, float step, Acc* out,
                 uint64_t& n) {
    const DF df;
    const DI di;
    const int lanes = int(hn::Lanes(df));
    HWY_ALIGN float ox[64], oy[64], oz[64], dx[64], dy[64], dz[64], t0[64];
    HWY_ALIGN int32_t tot[64];
    for (int i = 0; i < lanes; ++i) {
        ox[i] = rays[i].ox;
        oy[i] = rays[i].oy;
        oz[i] = rays[i].oz;
        dx[i] = rays[i].dx;
        dy[i] = rays[i].dy;
        dz[i] = rays[i].dz;
        t0[i] = rays[i].t0;
        tot[i] = rays[i].total;
    }
    const VF Ox = hn::Load(df, ox), Oy = hn::Load(df, oy), Oz = hn::Load(df, oz);
    const VF Dx = hn::Load(df, dx), Dy = hn::Load(df, dy), Dz = hn::Load(df, dz);
    const VF T0 = hn::Load(df, t0);
    const VI Tot = hn::Load(di, tot);
    VF R = hn::Zero(df), G = hn::Zero(df), B = hn::Zero(df), Tr = hn::Set(df, 1.0f);
    const VF ert = hn::Set(df, kErtT), one = hn::Set(df, 1.0f), step_ = hn::Set(df, step);
    const VF invStep = hn::Set(df, 1.0f / step), inv8 = hn::Set(df, 0.125f),
             eight = hn::Set(df, 8.0f);
    const float ldx = rays[0].dx, ldy = rays[0].dy, ldz = rays[0].dz;
    VI K = hn::Zero(di);
    uint64_t count = 0;
    for (;;) {
        const auto active = hn::And(hn::RebindMask(df, hn::Lt(K, Tot)), hn::Gt(Tr, ert));
        if (hn::AllFalse(df, active)) break;
        const VF t = hn::Add(T0, hn::Mul(hn::Add(hn::ConvertTo(df, K), hn::Set(df, 0.5f)), step_));
        VF qx = hn::Add(Ox, hn::Mul(Dx, t)), qy = hn::Add(Oy, hn::Mul(Dy, t)),
           qz = hn::Add(Oz, hn::Mul(Dz, t));
        const VI lx = hn::ConvertTo(di, hn::Mul(qx, inv8)),
                 ly = hn::ConvertTo(di, hn::Mul(qy, inv8)),
                 lz = hn::ConvertTo(di, hn::Mul(qz, inv8));
        auto sampling = active;
        if (L) {
            const VI idx = hn::IfThenElse(
                hn::RebindMask(di, active),
                hn::Add(hn::Mul(hn::Add(hn::Mul(lz, hn::Set(di, L->ly)), ly), hn::Set(di, L->lx)),
                        lx),
                hn::Zero(di));
            const VI occ = hn::GatherIndex(di, L->occ.data(), idx);
            sampling = hn::And(active, hn::RebindMask(df, hn::Ne(occ, hn::Zero(di))));
        }
        const auto leaping = hn::AndNot(sampling, active);
        VI Knext = hn::Add(K, hn::Set(di, 1));
        if (!hn::AllFalse(df, leaping)) {
            // exit of the lane's leaf
            auto plane = [&](VI l, VF d) {
                const VF base = hn::Mul(hn::ConvertTo(df, l), eight);
                return hn::IfThenElse(hn::Gt(d, hn::Zero(df)), hn::Add(base, eight), base);
            };
            auto texit = [&](VI l, VF o, VF d) {
                const VF te = hn::Div(hn::Sub(plane(l, d), o), d);
                return hn::IfThenElse(hn::Eq(d, hn::Zero(df)), hn::Set(df, 3e38f), te);
            };
            const VF te = hn::Min(hn::Min(texit(lx, Ox, Dx), texit(ly, Oy, Dy)), texit(lz, Oz, Dz));
            const VI kl = hn::ConvertTo(
                di, hn::Ceil(hn::Sub(hn::Mul(hn::Sub(te, T0), invStep), hn::Set(df, 0.5f))));
            Knext = hn::IfThenElse(hn::RebindMask(di, leaping), hn::Max(Knext, hn::Min(kl, Tot)),
                                   Knext);
        }
        if (!hn::AllFalse(df, sampling)) {
            count += hn::CountTrue(df, sampling);
            const VF safe = hn::Set(df, 2.0f);
            qx = hn::IfThenElse(sampling, qx, safe);
            qy = hn::IfThenElse(sampling, qy, safe);
            qz = hn::IfThenElse(sampling, qz, safe);
            VF r, g, b, a;
            if (sampleV(V, T, qx, qy, qz, ldx, ldy, ldz, r, g, b, a)) {
                a = hn::IfThenElseZero(sampling, a);
                const VF w = hn::Mul(Tr, a);
                R = hn::Add(R, hn::Mul(w, r));
                G = hn::Add(G, hn::Mul(w, g));
                B = hn::Add(B, hn::Mul(w, b));
                Tr = hn::Mul(Tr, hn::Sub(one, a));
            }
        }
        K = hn::IfThenElse(hn::RebindMask(di, active), Knext, K);
    }
    HWY_ALIGN float rr[64], gg[64], bb[64], tt[64];
    hn::Store(R, df, rr);
    hn::Store(G, df, gg);
    hn::Store(B, df, bb);
    hn::Store(Tr, df, tt);
    for (int i = 0; i < lanes; ++i)
        out[i] = {rr[i], gg[i], bb[i], tt[i]};
    n += count;
}

/// One frame with every ray: the chunk layout (`packets` false) or packets of Lanes() rays
/// (tiles 4 wide); returns the samples taken.
std::uint64_t RunFrame(const Vol& V, const Tf& T, const Leaves& L, const std::vector<Ray>& rays,
                       int width, int height, bool skip, bool packets, std::vector<Acc>& image) {
    std::uint64_t n = 0;
    if (!packets) {
        for (std::size_t i = 0; i < rays.size(); ++i) {
            image[i] = Acc{};
            marchChunks(V, T, skip ? &L : nullptr, rays[i], 1.0f, image[i], n);
        }
        return n;
    }
    const int lanes = int(hn::Lanes(DF()));
    const int tw = std::min(4, lanes), th = lanes / tw;
    std::vector<Ray> pk(static_cast<std::size_t>(lanes));
    std::vector<Acc> po(static_cast<std::size_t>(lanes));
    for (int by = 0; by < height; by += th)
        for (int bx = 0; bx < width; bx += tw) {
            for (int j = 0; j < lanes; ++j)
                pk[std::size_t(j)] =
                    rays[std::size_t(by + j / tw) * std::size_t(width) + std::size_t(bx + j % tw)];
            marchPacket(V, T, skip ? &L : nullptr, pk.data(), 1.0f, po.data(), n);
            for (int j = 0; j < lanes; ++j)
                image[std::size_t(by + j / tw) * std::size_t(width) + std::size_t(bx + j % tw)] =
                    po[std::size_t(j)];
        }
    return n;
}

const char* TargetName() {
    return hwy::TargetName(HWY_TARGET);
}

} // namespace HWY_NAMESPACE
} // namespace bc::bench
HWY_AFTER_NAMESPACE();

#if HWY_ONCE
namespace bc::bench {
HWY_EXPORT(RunFrame);
HWY_EXPORT(TargetName);
} // namespace bc::bench

int main(int argc, char** argv) {
    using namespace bc::bench;
    std::string scan = std::string(BC_SHARED_DATA_DIR) + "/stanford_cthead_256x256x113_uint16.raw";
    std::string tfName = "bone";
    bool skip = false;
    int reps = 7;
    for (int i = 1; i < argc; ++i) {
        const std::string a = argv[i];
        if (a == "--scan" && i + 1 < argc)
            scan = argv[++i];
        else if (a == "--tf" && i + 1 < argc)
            tfName = argv[++i];
        else if (a == "--skip")
            skip = true;
        else if (a == "--reps" && i + 1 < argc)
            reps = std::max(1, std::atoi(argv[++i]));
        else {
            std::fprintf(stderr, "usage: bc_bench_packets [--scan cthead.raw] [--tf bone|skin] "
                                 "[--skip] [--reps N]\n");
            return 2;
        }
    }
    if (tfName != "bone" && tfName != "skin") {
        std::fprintf(stderr, "bc_bench_packets: --tf: '%s' is not bone or skin\n", tfName.c_str());
        return 2;
    }
    const int nx = 256, ny = 256, nz = 113;
    std::vector<std::uint16_t> raw(std::size_t(nx) * ny * nz);
    std::ifstream in(scan, std::ios::binary);
    if (!in.read(reinterpret_cast<char*>(raw.data()), std::streamsize(raw.size() * 2))) {
        std::fprintf(stderr, "bc_bench_packets: %s: cannot read 256x256x113 u16\n", scan.c_str());
        return 1;
    }
    Vol V{nx, ny, nz, nx + 4, ny + 4, nz + 4, {}, 0, 0};
    V.v.assign(size_t(V.px) * V.py * V.pz + 64, 0);
    V.sy = V.px;
    V.sz = V.px * V.py;
    for (int z = 0; z < nz; ++z)
        for (int y = 0; y < ny; ++y)
            std::memcpy(&V.v[size_t(z + 2) * V.sz + size_t(y + 2) * V.sy + 2],
                        &raw[(size_t(z) * ny + y) * nx], nx * 2);
    const bool bone = tfName == "bone";
    Tf T;
    T.scale = 4095.0f / 3272.0f;
    T.rgba.assign(4096 * 4, 0.0f);
    for (int i = 0; i < 4096; ++i) {
        const float v = float(i) / T.scale;
        float a = 0;
        if (bone)
            a = std::clamp((v - 1150.0f) / 300.0f, 0.0f, 1.0f) * 0.8f;
        else
            a = std::clamp((v - 500.0f) / 400.0f, 0.0f, 1.0f) * 0.15f;
        T.rgba[4 * i] = 0.9f;
        T.rgba[4 * i + 1] = 0.8f;
        T.rgba[4 * i + 2] = 0.7f;
        T.rgba[4 * i + 3] = a;
    }
    // orthographic camera, direction from azimuth 30, elevation 20 (z stretched by spacing 2)
    const int W = 256, H = 256;
    const float az = 30 * 3.14159265f / 180, el = 20 * 3.14159265f / 180;
    float dx = -std::cos(el) * std::cos(az), dy = -std::cos(el) * std::sin(az), dz = -std::sin(el);
    // right and up
    float rx = -dy, ry = dx, rz = 0;
    float rl = std::sqrt(rx * rx + ry * ry);
    rx /= rl;
    ry /= rl;
    float ux = ry * dz - rz * dy, uy = rz * dx - rx * dz, uz = rx * dy - ry * dx;
    const float cx = V.px / 2.0f, cy = V.py / 2.0f, cz = V.pz / 2.0f, half = 190.0f;
    std::vector<Ray> rays(size_t(W) * H);
    const float step = 1.0f;
    for (int y = 0; y < H; ++y)
        for (int x = 0; x < W; ++x) {
            const float sx = (2.0f * (x + 0.5f) / W - 1.0f) * half,
                        sy = (1.0f - 2.0f * (y + 0.5f) / H) * half;
            Ray r{cx + sx * rx + sy * ux - 400 * dx,
                  cy + sx * ry + sy * uy - 400 * dy,
                  cz + sx * rz + sy * uz - 400 * dz,
                  dx,
                  dy,
                  dz,
                  0,
                  0};
            // box [2, n+1] minus a margin so trilinear + gradient stays inside the padding
            float t0 = 0, t1 = 1e30f;
            const float o[3] = {r.ox, r.oy, r.oz}, d[3] = {dx, dy, dz};
            const float lo[3] = {2.0f, 2.0f, 2.0f},
                        hi[3] = {float(nx) + 0.9f, float(ny) + 0.9f, float(nz) + 0.9f};
            bool miss = false;
            for (int a = 0; a < 3; ++a) {
                if (d[a] == 0) {
                    if (o[a] < lo[a] || o[a] > hi[a]) miss = true;
                    continue;
                }
                float ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
                t0 = std::max(t0, std::min(ta, tb));
                t1 = std::min(t1, std::max(ta, tb));
            }
            r.t0 = t0;
            r.total = miss || t1 <= t0 ? 0 : int((t1 - t0) / step - 0.5f);
            rays[size_t(y) * W + x] = r;
        }
    Leaves L;
    L.lx = (V.px + 7) / 8;
    L.ly = (V.py + 7) / 8;
    L.lz = (V.pz + 7) / 8;
    L.occ.assign(size_t(L.lx) * L.ly * L.lz + 64, 0);
    for (int lz = 0; lz < L.lz; ++lz)
        for (int ly = 0; ly < L.ly; ++ly)
            for (int lx = 0; lx < L.lx; ++lx) {
                int mn = 65535, mx = 0;
                for (int z = std::max(0, lz * 8 - 2); z < std::min(V.pz, lz * 8 + 10); ++z)
                    for (int y = std::max(0, ly * 8 - 2); y < std::min(V.py, ly * 8 + 10); ++y)
                        for (int x = std::max(0, lx * 8 - 2); x < std::min(V.px, lx * 8 + 10);
                             ++x) {
                            const int val = V.v[size_t(z) * V.sz + size_t(y) * V.sy + x];
                            mn = std::min(mn, val);
                            mx = std::max(mx, val);
                        }
                const int i0 = std::max(0, int(mn * T.scale) - 1),
                          i1 = std::min(4095, int(mx * T.scale) + 2);
                bool vis = false;
                for (int i = i0; i <= i1; ++i)
                    vis = vis || T.rgba[4 * i + 3] > 0.0f;
                L.occ[(size_t(lz) * L.ly + ly) * L.lx + lx] = vis;
            }
    std::vector<Acc> imgA(rays.size()), imgB(rays.size());
    std::printf("packet probe: cthead 256x256, orthographic 30,20, step 1, %s TF, %s, %s\n",
                tfName.c_str(), skip ? "8-voxel leaf skipping" : "no skipping",
                HWY_DYNAMIC_DISPATCH(TargetName)());
    std::printf("| rep | chunks ms | packets ms | chunks / packets | max diff | samples chunks / "
                "packets |\n|---:|---:|---:|---:|---:|---|\n");
    for (int rep = 0; rep < reps; ++rep) {
        auto s0 = std::chrono::steady_clock::now();
        const std::uint64_t nA =
            HWY_DYNAMIC_DISPATCH(RunFrame)(V, T, L, rays, W, H, skip, false, imgA);
        auto s1 = std::chrono::steady_clock::now();
        const std::uint64_t nB =
            HWY_DYNAMIC_DISPATCH(RunFrame)(V, T, L, rays, W, H, skip, true, imgB);
        auto s2 = std::chrono::steady_clock::now();
        const double ma = std::chrono::duration<double, std::milli>(s1 - s0).count(),
                     mb = std::chrono::duration<double, std::milli>(s2 - s1).count();
        double maxd = 0;
        for (std::size_t i = 0; i < rays.size(); ++i)
            maxd = std::max({maxd, double(std::abs(imgA[i].r - imgB[i].r)),
                             double(std::abs(imgA[i].g - imgB[i].g)),
                             double(std::abs(imgA[i].b - imgB[i].b)),
                             double(std::abs(imgA[i].t - imgB[i].t))});
        std::printf("| %d | %.1f | %.1f | %.2f | %.3g | %llu / %llu |\n", rep, ma, mb, ma / mb,
                    maxd, (unsigned long long)nA, (unsigned long long)nB);
    }
    return 0;
}
#endif

// brickcastd end to end on loopback: ten concurrent clients on different real scans,
// transfer functions, renderers and codecs; every frame a client receives equals a direct
// render of the same request (exactly for the CPU raycaster and the CPU splatter with
// lossless codecs; within the skipping invariant's 2/255 for the GPU raycaster, whose brick
// pool the daemon shares between sessions, and for the GPU splatter; within JPEG's bound for
// JPEG).
#include "ServerTestSupport.h"

#include "../render/RenderTestSupport.h"
#include "render/CpuRaycaster.h"
#include "render/GpuRaycaster.h"
#include "render/GpuSplatter.h"
#include "render/HybridSplatter.h"
#include "server/ViewRequest.h"

#include <mutex>

namespace bc::server::test {
namespace {

struct ClientPlan {
    std::string volume, tf, tfLater; ///< tfLater: switched to after the second frame
    protocol::Renderer renderer;
    protocol::Codec codec;
};

struct Received {
    protocol::SetCamera camera;
    protocol::SetTransferFunction tf;
    protocol::RenderOptions options;
    client::ReceivedFrame frame;
};

protocol::SetTransferFunction preset(const std::string& name) {
    protocol::SetTransferFunction tf;
    tf.preset = name;
    return tf;
}

/// Flies one client: 4 orbit frames, a TF switch half-way when the plan has one.
std::vector<Received> fly(const TestDaemon& d, const ClientPlan& plan, int seed) {
    client::Client c(d.clientConfig());
    const auto info = c.openVolume(plan.volume);
    protocol::RenderOptions o;
    o.width = 64;
    o.height = 48;
    o.renderer = plan.renderer;
    o.codec = plan.codec;
    o.quality = protocol::Quality::Refined;
    c.setRenderOptions(o);
    auto tf = preset(plan.tf);
    c.setTransferFunction(tf);
    std::vector<Received> out;
    for (int f = 0; f < 4; ++f) {
        if (f == 2 && !plan.tfLater.empty()) c.setTransferFunction(tf = preset(plan.tfLater));
        const auto camera = orbitCamera(info, 37.0 * seed + 50.0 * f, std::uint32_t(f + 1));
        c.setCamera(camera);
        c.requestFrame();
        out.push_back({camera, tf, o, c.nextFrame()});
    }
    c.bye();
    return out;
}

/// The frame a fresh renderer draws for the same request.
std::vector<std::uint8_t> directRender(bc::test::TestStore& t, const Received& r,
                                       render::GpuRaycaster& gpu, render::CpuRaycaster& cpu,
                                       render::HybridSplatter& splat,
                                       render::GpuSplatter& gpuSplat) {
    const auto tf =
        toTransferFunction(r.tf, render::VolumeValueStats::fromStore(t.store->info()), {});
    render::RenderOptions o = toRenderOptions(r.options, 1);
    o.shading = shadingFor(r.options, r.tf, *tf);
    o.level = r.frame.header.level;
    o.interactive = false;
    render::FrameStats stats;
    const auto camera = toCamera(r.camera);
    const auto renderer = r.options.renderer;
    const render::Image image = renderer == protocol::Renderer::CpuRaycaster
                                    ? cpu.render(*t.store, *t.cache, *tf, camera, o, stats)
                                : renderer == protocol::Renderer::Splatter
                                    ? splat.render(*t.store, *t.cache, *tf, camera, o, stats)
                                : renderer == protocol::Renderer::GpuSplatter
                                    ? gpuSplat.render(*t.store, *t.cache, *tf, camera, o, stats)
                                    : gpu.render(*t.store, *t.cache, *tf, camera, o, stats);
    return render::toRgba8(image);
}

int maxAbsDiff(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
    int worst = a.size() == b.size() ? 0 : 256;
    for (std::size_t i = 0; i < std::min(a.size(), b.size()); ++i)
        worst = std::max(worst, std::abs(int(a[i]) - int(b[i])));
    return worst;
}

double meanAbsDiffRgb(const std::vector<std::uint8_t>& a, const std::vector<std::uint8_t>& b) {
    double sum = 0;
    for (std::size_t i = 0; i < a.size(); i += 4)
        for (int k = 0; k < 3; ++k)
            sum += std::abs(int(a[i + k]) - int(b[i + k]));
    return sum / double(a.size() / 4 * 3);
}

TEST(DaemonEndToEnd, TenConcurrentClientsEachReceiveTheDirectRenderOfTheirRequest) {
    const std::vector<std::string> scans = {"cthead", "CT_AVM", "headsq", "hydrogen"};
    std::map<std::string, std::unique_ptr<bc::test::TestStore>> stores;
    bc::test::glContext();
    for (const auto& s : scans) {
        auto spec = bc::test::realScan(s);
        if (!spec) return bc::test::missingData("scan " + s);
        stores[s] = bc::test::ingestSpec(*spec, {32, 2, 8});
    }
    DaemonConfig config;
    config.source = "<test>";
    for (const auto& s : scans) {
        CatalogEntry e;
        e.name = s;
        e.store = stores[s]->store->path();
        config.volumes.push_back(e);
    }
    using R = protocol::Renderer;
    using C = protocol::Codec;
    const std::vector<ClientPlan> plans = {
        {"cthead", "ct-skin", "ct-bone", R::CpuRaycaster, C::Zstd},
        {"cthead", "ct-bone", "", R::GpuRaycaster, C::ZstdDelta},
        {"CT_AVM", "vessels", "", R::CpuRaycaster, C::Raw},
        {"CT_AVM", "vessels", "ct-skin", R::GpuRaycaster, C::Zstd},
        {"headsq", "mr", "", R::CpuRaycaster, C::ZstdDelta},
        {"headsq", "ct-bone", "", R::GpuRaycaster, C::Jpeg},
        {"hydrogen", "smoke", "", R::CpuRaycaster, C::Jpeg},
        {"hydrogen", "smoke", "mr", R::GpuRaycaster, C::Raw},
        {"headsq", "ct-skin", "", R::Splatter, C::Zstd},    // the second renderer, by protocol
        {"hydrogen", "smoke", "", R::GpuSplatter, C::Zstd}, // and its OpenGL path
    };
    std::vector<std::vector<Received>> got(plans.size());
    {
        TestDaemon daemon(config);
        std::vector<std::thread> threads;
        std::mutex failures;
        std::vector<std::string> errors;
        for (std::size_t i = 0; i < plans.size(); ++i)
            threads.emplace_back([&, i] {
                try {
                    got[i] = fly(daemon, plans[i], int(i));
                } catch (const std::exception& e) {
                    std::lock_guard lock(failures);
                    errors.push_back("client " + std::to_string(i) + ": " + e.what());
                }
            });
        for (auto& t : threads)
            t.join();
        for (const auto& e : errors)
            ADD_FAILURE() << e;
    }
    for (std::size_t i = 0; i < plans.size(); ++i) {
        const auto& plan = plans[i];
        ASSERT_EQ(got[i].size(), 4u) << "client " << i;
        render::GpuRaycaster gpu;
        render::CpuRaycaster cpu;
        render::HybridSplatter splat;
        render::GpuSplatter gpuSplat;
        for (const auto& r : got[i]) {
            const auto direct = directRender(*stores[plan.volume], r, gpu, cpu, splat, gpuSplat);
            ASSERT_EQ(r.frame.rgba.size(), direct.size());
            const std::string what = "client " + std::to_string(i) + " " + plan.volume +
                                     " camera " + std::to_string(r.frame.header.cameraId);
            EXPECT_EQ(r.frame.header.cameraId, r.camera.cameraId) << what;
            if (plan.codec == C::Jpeg) {
                EXPECT_LT(meanAbsDiffRgb(r.frame.rgba, direct), 3.0) << what;
            } else if (plan.renderer != R::GpuRaycaster && plan.renderer != R::GpuSplatter) {
                // CPU renderers are deterministic
                EXPECT_EQ(maxAbsDiff(r.frame.rgba, direct), 0) << what;
            } else {
                EXPECT_LE(maxAbsDiff(r.frame.rgba, direct), 2) << what;
            }
        }
    }
}

} // namespace
} // namespace bc::server::test

// The metrics brickcastd exports: the Prometheus text format and histograms on
// their own; then a daemon's counters against a scripted path whose misses can be counted
// by hand, the same numbers through GET /metrics and the Stats message, and bad scrapes
// answered with a status while a client keeps getting frames.
#include "ServerTestSupport.h"

#include "server/Metrics.h"

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sstream>

namespace bc::server::test {
namespace {

TEST(Metrics, HistogramCountsBucketsAndEstimatesQuantilesLikePrometheus) {
    Histogram h({1, 2, 5, 10});
    for (double v : {0.5, 1.0, 1.5, 3.0, 4.0, 7.0, 20.0})
        h.observe(v);
    h.observe(std::nan(""));
    EXPECT_EQ(h.count(), 7u);
    EXPECT_DOUBLE_EQ(h.sum(), 37.0);
    EXPECT_EQ(h.counts(), (std::vector<std::uint64_t>{2, 1, 2, 1, 1})); // le 1, 2, 5, 10, +Inf
    // rank 3.5 of 7 lies in (2, 5]: 2 + 3 * (3.5 - 3) / 2
    EXPECT_DOUBLE_EQ(h.quantile(0.5), 2.75);
    EXPECT_DOUBLE_EQ(h.quantile(0.99), 10.0) << "the +Inf bucket reads as the highest bound";
    EXPECT_TRUE(std::isnan(Histogram({1}).quantile(0.5)));
    EXPECT_THROW(Histogram({2, 1}), std::invalid_argument);
    EXPECT_THROW(Histogram({}), std::invalid_argument);
    EXPECT_EQ(Histogram::series125(1, 100), (std::vector<double>{1, 2, 5, 10, 20, 50, 100}));
    EXPECT_EQ(Histogram::geometric(1, 64, 4), (std::vector<double>{1, 4, 16, 64}));
}

TEST(Metrics, TextExpositionHasHelpTypeEscapedLabelsAndCumulativeBuckets) {
    MetricSet m;
    m.counter("hits_total", "Hits\nof bricks", 3, {{"volume", "a\"b\\c"}});
    m.counter("hits_total", "Hits\nof bricks", 4, {{"volume", "d"}});
    m.gauge("resident_bytes", "Bytes", 1.5);
    Histogram h({1, 10});
    h.observe(0.5);
    h.observe(5);
    h.observe(50);
    m.histogram("latency_ms", "Latency", h, {{"renderer", "cpu"}});
    const std::string text = m.prometheusText();
    EXPECT_EQ(text, "# HELP brickcast_hits_total Hits\\nof bricks\n"
                    "# TYPE brickcast_hits_total counter\n"
                    "brickcast_hits_total{volume=\"a\\\"b\\\\c\"} 3\n"
                    "brickcast_hits_total{volume=\"d\"} 4\n"
                    "# HELP brickcast_resident_bytes Bytes\n"
                    "# TYPE brickcast_resident_bytes gauge\n"
                    "brickcast_resident_bytes 1.5\n"
                    "# HELP brickcast_latency_ms Latency\n"
                    "# TYPE brickcast_latency_ms histogram\n"
                    "brickcast_latency_ms_bucket{renderer=\"cpu\",le=\"1\"} 1\n"
                    "brickcast_latency_ms_bucket{renderer=\"cpu\",le=\"10\"} 2\n"
                    "brickcast_latency_ms_bucket{renderer=\"cpu\",le=\"+Inf\"} 3\n"
                    "brickcast_latency_ms_sum{renderer=\"cpu\"} 55.5\n"
                    "brickcast_latency_ms_count{renderer=\"cpu\"} 3\n");
    const auto flat = m.statCounters(128);
    ASSERT_EQ(flat.size(), 7u);
    EXPECT_EQ(flat[1].first, "hits_total{volume=\"d\"}");
    EXPECT_EQ(flat[3].first, "latency_ms_count{renderer=\"cpu\"}");
    EXPECT_EQ(flat[3].second, 3.0);
    EXPECT_EQ(m.statCounters(5)[0].first, "hits_");
    EXPECT_EQ(m.value("hits_total", {{"volume", "d"}}), 4.0);
    EXPECT_THROW(m.value("nothing"), std::out_of_range);
    EXPECT_THROW(m.counter("hits", "no _total suffix", 1), std::invalid_argument);
    EXPECT_THROW(m.gauge("Bad-Name", "x", 1), std::invalid_argument);
    EXPECT_THROW(m.gauge("resident_bytes", "other help", 1), std::invalid_argument);
    EXPECT_THROW(m.gauge("g", "x", 1, {{"le", "1"}}), std::invalid_argument);
}

/// The whole reply to `request` sent on a fresh connection to 127.0.0.1:port.
/// A stored brick of the generated u16 phantom: 64^3 voxels and a 2-voxel apron.
constexpr std::uint64_t kBrickBytes = 68ull * 68 * 68 * 2;

class DaemonMetrics : public ::testing::Test {
  protected:
    void SetUp() override {
        DaemonConfig c = generatedConfig(dir, {{"m", 160}});
        c.metricsHost = "127.0.0.1";
        c.metricsPort = 0;
        c.hostBudgetBytes = kBrickBytes; // one brick stays resident once a frame unpins them
        // Frames drawn whole, in one pass: the counts below are those of one plan per frame (a
        // first frame would otherwise be sliced, its renderer's speed not yet measured).
        c.sliceMs = 600000;
        c.frameCacheBytes = 0; // the same view is drawn twice (FrameCacheTest has the cache)
        daemon = std::make_unique<TestDaemon>(c);
        port = daemon->daemon->metricsPort();
        ASSERT_NE(port, 0);
    }
    std::string metrics() {
        const std::string reply = scrape(port, "GET /metrics HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n");
        EXPECT_TRUE(reply.starts_with("HTTP/1.1 200 OK\r\n")) << reply.substr(0, 200);
        EXPECT_NE(reply.find("Content-Type: text/plain; version=0.0.4"), std::string::npos);
        return reply.substr(reply.find("\r\n\r\n") + 4);
    }
    TempDir dir;
    std::unique_ptr<TestDaemon> daemon;
    std::uint16_t port = 0;
};

// A budget of one brick against a working set of W: frame 1 loads its W bricks (W misses,
// every byte of its working set loaded) and unpinning them at its end evicts all but the
// last (W - 1 evictions). Frame 2 of the same view pins the same W; its first load evicts
// that last one before its turn comes (only unpinned bricks can go), so all W miss again,
// each a re-fetch, and W more are evicted: LRU thrashing, counted.
TEST_F(DaemonMetrics, HostTierCountersFollowAScriptedPathCountedByHand) {
    client::Client c(daemon->clientConfig());
    const auto v = c.openVolume("m");
    c.setRenderOptions(smallCpuFrames(48));
    c.setCamera(orbitCamera(v, 30, 1));
    c.requestFrame();
    c.nextFrame();
    const std::string cpu = "{renderer=\"cpu\"}", vol = "{volume=\"m\"}";
    std::string t = metrics();
    const double w = sampleOf(t, "brickcast_host_cache_misses_total" + vol);
    const double loaded = sampleOf(t, "brickcast_host_cache_bytes_loaded_total" + vol);
    std::printf("[metrics] frame 1: %.0f bricks, %.0f bytes\n", w, loaded);
    ASSERT_GT(w, 1);
    ASSERT_EQ(loaded, w * double(kBrickBytes)) << "the generated store's bricks changed size";
    EXPECT_EQ(sampleOf(t, "brickcast_frames_total" + cpu), 1);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_hits_total" + vol), 0);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_refetches_total" + vol), 0);
    EXPECT_EQ(sampleOf(t, "brickcast_frame_working_set_bytes_sum"), loaded);
    EXPECT_EQ(sampleOf(t, "brickcast_frame_working_set_bytes_count"), 1);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_evictions_total" + vol), w - 1);
    EXPECT_EQ(sampleOf(t, "brickcast_sessions"), 1);
    EXPECT_EQ(sampleOf(t, "brickcast_frame_latency_ms_count"), 1);

    c.requestFrame();
    c.nextFrame();
    t = metrics();
    EXPECT_EQ(sampleOf(t, "brickcast_frames_total" + cpu), 2);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_misses_total" + vol), 2 * w);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_hits_total" + vol), 0);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_refetches_total" + vol), w);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_bytes_refetched_total" + vol), loaded);
    EXPECT_EQ(sampleOf(t, "brickcast_host_cache_evictions_total" + vol), 2 * w - 1);
    EXPECT_EQ(sampleOf(t, "brickcast_frame_working_set_bytes_sum"), 2 * loaded);

    // The Stats message carries the same counters under the same names.
    double statsMisses = -1;
    for (const auto& [name, value] : c.stats())
        if (name == "host_cache_misses_total" + vol) statsMisses = value;
    EXPECT_EQ(statsMisses, 2 * w);
}

TEST_F(DaemonMetrics, BadScrapesGetAStatusAndClientsKeepTheirFrames) {
    client::Client c(daemon->clientConfig());
    const auto v = c.openVolume("m");
    c.setRenderOptions(smallCpuFrames(32));
    c.setCamera(orbitCamera(v, 30, 1));
    auto status = [&](const std::string& request) {
        const std::string r = scrape(port, request);
        return r.substr(0, r.find("\r\n"));
    };
    EXPECT_EQ(status("POST /metrics HTTP/1.1\r\n\r\n"), "HTTP/1.1 405 Method Not Allowed");
    EXPECT_EQ(status("GET /secrets HTTP/1.1\r\n\r\n"), "HTTP/1.1 404 Not Found");
    EXPECT_EQ(status("hello\r\n\r\n"), "HTTP/1.1 400 Bad Request");
    EXPECT_EQ(status(std::string(9000, 'x')), "HTTP/1.1 431 Request Header Fields Too Large");
    EXPECT_EQ(status("GET /metrics HTTP/1.1\r\nHost: evil.example:9100\r\n\r\n"),
              "HTTP/1.1 403 Forbidden")
        << "a page whose name was rebound to the metrics address reads nothing";
    EXPECT_EQ(status("GET /metrics HTTP/1.1\r\nhost:  localhost:9100 \r\n\r\n"), "HTTP/1.1 200 OK");
    EXPECT_EQ(status("GET /metrics HTTP/1.1\r\n"), "HTTP/1.1 408 Request Timeout")
        << "a request head that never ends is cut after 2 s";
    const std::string head = scrape(port, "HEAD /metrics HTTP/1.1\r\n\r\n");
    EXPECT_TRUE(head.starts_with("HTTP/1.1 200 OK")) << head;
    EXPECT_EQ(head.find("# TYPE"), std::string::npos) << "HEAD has no body";
    c.requestFrame();
    EXPECT_EQ(c.nextFrame().header.width, 32u);
    EXPECT_NE(metrics().find("brickcast_frames_total{renderer=\"cpu\"} 1\n"), std::string::npos);
}

} // namespace
} // namespace bc::server::test

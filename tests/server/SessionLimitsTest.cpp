// What one client can make the daemon do, whoever it is: a session that never reads its
// replies holds a bounded queue and is cut at the write deadline; connections that never
// authenticate take no authenticated client's place; wrong tokens from one address slow down.
// A witness client keeps being served through each.
#include "ServerTestSupport.h"

#include "server/detail/AuthThrottle.h"
#include "server/detail/Session.h"

#include <atomic>
#include <fstream>

namespace bc::server::test {
namespace {

using protocol::ErrorCode;
using Clock = std::chrono::steady_clock;
constexpr const char* kToken = "correct horse battery staple";

/// This process's resident memory (the daemon runs in it), in bytes.
std::uint64_t residentBytes() {
    std::ifstream statm("/proc/self/statm");
    std::uint64_t size = 0, resident = 0;
    statm >> size >> resident;
    return resident * std::uint64_t(::sysconf(_SC_PAGESIZE));
}

TEST(AuthThrottle, EachWrongTokenDoublesTheAddresssWaitUpToTwoSeconds) {
    detail::AuthThrottle t;
    const auto t0 = Clock::time_point{} + std::chrono::hours(1);
    EXPECT_EQ(t.admit("10.0.0.1", t0), t0) << "an address with no failures waits for nothing";
    std::vector<long> waits;
    auto now = t0;
    for (int i = 0; i < 7; ++i) {
        now = *t.admit("10.0.0.1", now);
        waits.push_back(t.failed("10.0.0.1", now).count());
    }
    EXPECT_EQ(waits, (std::vector<long>{100, 200, 400, 800, 1600, 2000, 2000}));
    EXPECT_EQ(t.admit("10.0.0.2", now), now) << "another address is not slowed";
    // Auths from several connections at once: one waits its turn, the others are refused.
    const auto delayed = t.delayed();
    const auto first = t.admit("10.0.0.1", now);
    ASSERT_TRUE(first);
    EXPECT_EQ(*first, now + std::chrono::milliseconds(2000));
    EXPECT_FALSE(t.admit("10.0.0.1", now)) << "a second Auth while one waits";
    EXPECT_EQ(t.delayed(), delayed + 1);
    // Its connection went: the next may wait, behind the turn the first had taken.
    t.abandoned("10.0.0.1");
    EXPECT_EQ(t.admit("10.0.0.1", now), *first + std::chrono::milliseconds(2000));
    t.succeeded("10.0.0.1");
    EXPECT_EQ(t.admit("10.0.0.1", now), now) << "a correct token starts the address afresh";
    t.failed("10.0.0.3", now);
    const auto later = now + detail::AuthThrottle::kForgetAfter + std::chrono::seconds(1);
    EXPECT_EQ(t.admit("10.0.0.3", later), later) << "a quiet minute forgets the address";
    for (int i = 0; i < 5000; ++i)
        t.failed("10.1." + std::to_string(i / 256) + "." + std::to_string(i % 256), now);
    EXPECT_LE(t.addresses(), detail::AuthThrottle::kMaxAddresses);
}

/// Connections that connect and send nothing, kept at `count` (reopened as the daemon cuts
/// them) until stopped.
class SilentConnections {
  public:
    SilentConnections(std::uint16_t port, std::size_t count)
        : mThread([this, port, count] { run(port, count); }) {}
    ~SilentConnections() { stop(); }
    void stop() {
        mStop = true;
        if (mThread.joinable()) mThread.join();
    }

  private:
    void run(std::uint16_t port, std::size_t count) {
        std::vector<std::unique_ptr<RawConnection>> held;
        while (!mStop) {
            std::erase_if(held, [](auto& c) { return c->peerGone(); });
            while (held.size() < count && !mStop)
                held.push_back(std::make_unique<RawConnection>(port));
            std::this_thread::sleep_for(std::chrono::milliseconds(20));
        }
    }
    std::atomic<bool> mStop = false;
    std::thread mThread;
};

class SessionLimits : public ::testing::Test {
  protected:
    static void SetUpTestSuite() {
        sDir = new TempDir;
        DaemonConfig c = generatedConfig(*sDir, {{"phantom", 40}});
        c.token = kToken;
        c.handshakeTimeoutMs = 1500;
        c.writeTimeoutMs = 1500;
        sDaemon = new TestDaemon(c);
    }
    static void TearDownTestSuite() {
        delete sDaemon;
        delete sDir;
    }
    void SetUp() override {
        mWitness = std::make_unique<client::Client>(sDaemon->clientConfig(kToken));
        mVolume = mWitness->openVolume("phantom");
        mWitness->setRenderOptions(smallCpuFrames(32));
    }
    /// The witness asks for a frame and gets it.
    void witnessFrame(std::uint32_t id) {
        mWitness->setCamera(orbitCamera(mVolume, 10.0 * id, id));
        mWitness->requestFrame();
        EXPECT_EQ(mWitness->nextFrame().header.cameraId, id);
    }

    static inline TempDir* sDir = nullptr;
    static inline TestDaemon* sDaemon = nullptr;
    std::unique_ptr<client::Client> mWitness;
    protocol::VolumeInfo mVolume;
};

TEST_F(SessionLimits, AClientThatNeverReadsItsRepliesHoldsABoundedQueueAndIsCut) {
    witnessFrame(1);
    const std::uint64_t before = residentBytes();
    RawConnection attacker(sDaemon->port, 4096);
    attacker.handshake(kToken);
    // 300,000 RequestStats (4.8 MB), each answered with about 4 KiB, never read. The sends
    // block once the daemon stops reading; they fail once it cuts the connection.
    std::atomic<bool> sent = false;
    std::thread flood([&] {
        std::vector<std::uint8_t> burst;
        for (int i = 0; i < 1000; ++i)
            protocol::encode(protocol::RequestStats{}, std::uint32_t(10 + i), burst);
        for (int i = 0; i < 300; ++i)
            attacker.send(burst);
        sent = true;
    });
    struct JoinAtExit {
        std::thread& thread;
        ~JoinAtExit() { thread.join(); } // the daemon's cut ends the sends
    } joinFlood{flood};
    double queuedMax = 0, worstGapS = 0;
    std::uint32_t id = 2;
    auto last = Clock::now();
    for (auto until = last + std::chrono::seconds(2); Clock::now() < until;) {
        witnessFrame(id++);
        queuedMax = std::max(queuedMax, serverStat(*mWitness, "write_queue_bytes_max"));
        worstGapS = std::max(worstGapS, std::chrono::duration<double>(Clock::now() - last).count());
        last = Clock::now();
    }
    std::printf("[doors] witness's worst gap %.3f s, largest queue %.0f bytes\n", worstGapS,
                queuedMax);
    // Loose: a loaded machine may be slow; what is bounded is that the flood takes no turns.
    EXPECT_LT(worstGapS, 5.0) << "the witness waited behind the flood";
    EXPECT_LE(queuedMax, double(detail::Session::kMaxQueuedReplyBytes + (64 << 10)))
        << "replies queued for a client that does not read them";
    EXPECT_EQ(sessionsDownTo(*mWitness, 1.0, 30), 1.0) << "not cut at the write deadline";
    witnessFrame(id++);
    const double grewMb = (double(residentBytes()) - double(before)) / double(1 << 20);
    std::printf("[doors] resident memory grew %.1f MiB\n", grewMb);
    EXPECT_LT(grewMb, 64.0) << "the daemon grew by " << grewMb << " MiB";
}

TEST_F(SessionLimits, RequestsAskedAgainBeforeTheirReplyWentAreEachAnswered) {
    RawConnection c(sDaemon->port);
    c.handshake(kToken);
    std::vector<std::uint8_t> burst;
    for (std::uint32_t i = 0; i < 200; ++i)
        protocol::encode(protocol::RequestStats{}, 100 + i, burst);
    c.send(burst);
    for (std::uint32_t i = 0; i < 200; ++i) {
        std::uint32_t request = 0;
        const auto m = c.next(10000, &request);
        ASSERT_TRUE(m && std::holds_alternative<protocol::Stats>(*m)) << "reply " << i;
        EXPECT_EQ(request, 100 + i) << "each reply carries its own request's id";
    }
}

TEST_F(SessionLimits, ConnectionsThatNeverAuthenticateKeepNoAuthenticatedClientOut) {
    // Forty silent connections (over max_unauthenticated), reopened as the daemon cuts them.
    SilentConnections silent(sDaemon->port, 40);
    // They fill the places for connections yet to authenticate: the daemon cuts the oldest.
    EXPECT_GT(waitForStat(*mWitness, "connections_unauthenticated_cut_total",
                          [](double n) { return n > 0; }),
              0.0);
    std::vector<std::unique_ptr<client::Client>> clients; // the witness is one already
    for (std::uint32_t i = 1; i < DaemonConfig{}.maxClients; ++i) {
        try {
            clients.push_back(std::make_unique<client::Client>(sDaemon->clientConfig(kToken)));
            EXPECT_EQ(clients.back()->listVolumes().size(), 1u) << "client " << i;
        } catch (const std::exception& e) {
            ADD_FAILURE() << "client " << i << " was not served: " << e.what();
        }
    }
    witnessFrame(3);
    EXPECT_GT(serverStat(*mWitness, "connections_unauthenticated_cut_total"), 0.0);
    silent.stop();
    // Every place is taken by an authenticated client now: one more is refused.
    RawConnection extra(sDaemon->port);
    const auto busy = extra.nextError();
    ASSERT_TRUE(busy);
    EXPECT_EQ(busy->code, ErrorCode::Busy);
}

TEST(SessionLimitsAuth, WrongTokensFromOneAddressComeAtMostTenASecond) {
    TempDir dir;
    DaemonConfig config = generatedConfig(dir, {{"phantom", 32}});
    config.token = kToken;
    TestDaemon daemon(config);
    std::atomic<int> answered = 0;
    std::atomic<bool> stop = false;
    std::vector<std::thread> guessers;
    for (int g = 0; g < 4; ++g)
        guessers.emplace_back([&, g] {
            for (int i = 0; !stop; ++i) {
                try {
                    RawConnection c(daemon.port);
                    c.send(protocol::Hello{}, 1);
                    if (!c.next(3000)) continue;
                    c.send(protocol::Auth{"guess " + std::to_string(g) + "-" + std::to_string(i)},
                           2);
                    if (auto e = c.nextError(3000); e && e->code == ErrorCode::AuthFailed)
                        ++answered;
                } catch (const std::exception&) { // refused at connect: try again
                }
            }
        });
    const auto start = Clock::now();
    std::this_thread::sleep_for(std::chrono::seconds(3));
    stop = true;
    for (auto& g : guessers)
        g.join();
    const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
    std::printf("[doors] %d wrong tokens checked in %.1f s from one address\n", answered.load(),
                seconds);
    EXPECT_LE(double(answered), 10.0 * seconds)
        << answered << " wrong tokens checked in " << seconds << " s";
    EXPECT_GE(answered.load(), 3) << "wrong tokens are still answered, only slower";
    // The right token from the same address is served, after its turn.
    client::Client c(daemon.clientConfig(kToken));
    EXPECT_EQ(c.listVolumes().size(), 1u);
    EXPECT_GE(serverStat(c, "auth_failures_total"), double(answered));
    EXPECT_GT(serverStat(c, "auth_delayed_total"), 0.0);
}

} // namespace
} // namespace bc::server::test

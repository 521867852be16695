// brickcastd under mpirun: 2 and 4 ranks serve every frame of an orbit as one
// brickcastd process does (two real scans and a generated volume larger than each rank's host
// budget; exact but for float rounding with early termination off, within its bound on), a
// volume of fewer bricks than ranks; SIGTERM to rank 0 stops every rank; a rank killed or
// stopped fails the frames with an error naming it within the timeout, the front end keeps
// answering, and SIGTERM to rank 0 then ends the ranks alive; ranks with different configs, or
// one that cannot open its store, refuse to start with one line naming the rank.
#include "tests/server/ServerTestSupport.h"

#include <algorithm>
#include <csignal>
#include <fcntl.h>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <sstream>
#include <string>
#include <sys/wait.h>
#include <vector>

namespace bc::server::test {
namespace {

#ifdef BC_MPIEXEC
/// An mpirun job started in the background, its output in a file.
struct Job {
    pid_t pid = -1;
    std::string output; ///< file of its stdout and stderr
    client::ClientConfig client;
    bool started = false; ///< rank 0 wrote its port file

    std::string text() const {
        std::ifstream in(output);
        std::stringstream s;
        s << in.rdbuf();
        return s.str();
    }
};

/// Runs `mpirun --allow-run-as-root --oversubscribe ARGS...` (as root in CI, more ranks than
/// cores); waits up to `startS` for `portFile` when given.
Job startJob(const TempDir& dir, const std::vector<std::string>& args, const std::string& portFile,
             int startS = 60) {
    Job job;
    job.output = dir.file("mpirun-" + std::to_string(::time(nullptr)) + "-" +
                          std::to_string(::getpid()) + ".log");
    std::vector<std::string> all{BC_MPIEXEC, "--allow-run-as-root", "--oversubscribe"};
    all.insert(all.end(), args.begin(), args.end());
    job.pid = ::fork();
    if (job.pid == 0) {
        const int fd = ::open(job.output.c_str(), O_WRONLY | O_CREAT | O_TRUNC, 0644);
        ::dup2(fd, 1);
        ::dup2(fd, 2);
        const int none = ::open("/dev/null", O_RDONLY); // mpirun forwards stdin to rank 0
        ::dup2(none, 0);
        ::setpgid(0, 0); // its own group: the test can end the whole job
        std::vector<char*> argv;
        for (auto& a : all)
            argv.push_back(a.data());
        argv.push_back(nullptr);
        ::execv(argv[0], argv.data());
        std::_Exit(127);
    }
    if (portFile.empty()) return job;
    for (int i = 0; i < startS * 20 && !std::filesystem::exists(portFile); ++i) {
        int status = 0;
        if (::waitpid(job.pid, &status, WNOHANG) == job.pid) {
            job.pid = -1; // ended before listening
            return job;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    job.started = std::filesystem::exists(portFile);
    if (job.started) std::ifstream(portFile) >> job.client.port;
    job.client.timeoutMs = 120000;
    return job;
}

/// The job's exit status within `timeoutS`; nullopt (and the job killed) when it does not end.
std::optional<int> waitForJob(Job& job, int timeoutS) {
    if (job.pid < 0) return 0;
    int status = 0;
    for (int i = 0; i < timeoutS * 20; ++i) {
        if (::waitpid(job.pid, &status, WNOHANG) == job.pid) {
            job.pid = -1;
            return status;
        }
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    ::kill(-job.pid, SIGKILL);
    ::waitpid(job.pid, &status, 0);
    job.pid = -1;
    return std::nullopt;
}

/// The pid of rank `rank` of the job (a child of mpirun with OMPI_COMM_WORLD_RANK=rank), or
/// of any rank when `rank` is -1; -1 when there is none.
pid_t rankPid(const Job& job, int rank) {
    for (const auto& entry : std::filesystem::directory_iterator("/proc")) {
        const std::string name = entry.path().filename();
        if (name.find_first_not_of("0123456789") != std::string::npos) continue;
        std::ifstream stat(entry.path() / "stat");
        std::string line;
        std::getline(stat, line);
        const auto close = line.rfind(')');
        if (close == std::string::npos) continue;
        std::istringstream rest(line.substr(close + 2));
        char state = 0;
        pid_t parent = 0;
        rest >> state >> parent;
        if (parent != job.pid) continue;
        std::ifstream env(entry.path() / "environ");
        std::string var;
        while (std::getline(env, var, '\0'))
            if (var.starts_with("OMPI_COMM_WORLD_RANK=") &&
                (rank < 0 || var == "OMPI_COMM_WORLD_RANK=" + std::to_string(rank)))
                return std::stoi(name);
    }
    return -1;
}

/// Whether every rank of `ranks` has ended (is no live child of mpirun) within `timeoutS`.
bool ranksEnd(const Job& job, const std::vector<int>& ranks, int timeoutS) {
    for (int i = 0; i < timeoutS * 20; ++i) {
        if (std::none_of(ranks.begin(), ranks.end(), [&](int r) { return rankPid(job, r) > 0; }))
            return true;
        std::this_thread::sleep_for(std::chrono::milliseconds(50));
    }
    return false;
}

/// Ends a job left running (a failed assertion): SIGTERM to mpirun (it ends its ranks), then
/// SIGKILL to it and to every rank left (each rank has a process group of its own).
struct JobGuard {
    Job& job;
    ~JobGuard() {
        if (job.pid <= 0) return;
        std::vector<pid_t> ranks;
        for (pid_t p; (p = rankPid(job, -1)) > 0 && ranks.size() < 64;) {
            ranks.push_back(p);
            ::kill(p, SIGKILL);
        }
        ::kill(job.pid, SIGTERM);
        if (!waitForJob(job, 10)) return; // killed by waitForJob
    }
};
#endif

/// The transfer function preset `name`.
protocol::SetTransferFunction preset(const std::string& name) {
    protocol::SetTransferFunction t;
    t.kind = protocol::TfKind::Preset;
    t.preset = name;
    return t;
}

/// Frames of one orbit of `volume`, as a client of `config` sees them (raw codec: exact).
std::vector<client::ReceivedFrame> orbit(const client::ClientConfig& config,
                                         const std::string& volume, const std::string& tf,
                                         protocol::Renderer renderer, bool ert, int frames) {
    client::Client c(config);
    const auto v = c.openVolume(volume);
    c.setTransferFunction(preset(tf));
    protocol::RenderOptions o = smallCpuFrames(72);
    o.renderer = renderer;
    o.codec = protocol::Codec::Raw;
    if (!ert) o.techniques &= ~protocol::kTechEarlyTermination;
    c.setRenderOptions(o);
    std::vector<client::ReceivedFrame> out;
    for (int i = 0; i < frames; ++i) {
        c.setCamera(orbitCamera(v, 360.0 * i / frames + 15, std::uint32_t(i + 1)));
        c.requestFrame();
        out.push_back(c.nextFrame());
    }
    return out;
}

/// One frame of each mode (MIP, the isosurface at the middle value, the average, composite
/// with the cuts capped), cut to a box and a plane, of one view.
std::vector<client::ReceivedFrame> cutModes(const client::ClientConfig& config,
                                            const std::string& volume) {
    client::Client c(config);
    const auto v = c.openVolume(volume);
    c.setTransferFunction(preset("ct-bone"));
    protocol::RenderOptions o = smallCpuFrames(72);
    o.codec = protocol::Codec::Raw;
    o.techniques &= ~protocol::kTechEarlyTermination;
    c.setRenderOptions(o);
    protocol::SetModeAndClip m;
    m.cropped = true;
    for (int a = 0; a < 3; ++a) {
        m.cropMin[a] = 0.1 * v.dims[a] * v.spacingMm[a];
        m.cropMax[a] = 0.8 * v.dims[a] * v.spacingMm[a];
    }
    m.planes = {protocol::ClipPlane{{1, 0.3, 0}, -0.4 * v.dims[0] * v.spacingMm[0]}};
    std::vector<client::ReceivedFrame> out;
    std::uint32_t id = 1;
    for (const auto mode : {protocol::BlendMode::Maximum, protocol::BlendMode::Isosurface,
                            protocol::BlendMode::Average, protocol::BlendMode::Composite}) {
        m.mode = mode;
        m.cap = mode == protocol::BlendMode::Composite; // the cuts' faces drawn
        m.isoValue = mode == protocol::BlendMode::Isosurface ? 0.5 * (v.valueMin + v.valueMax) : 0;
        c.setModeAndClip(m);
        if (mode == protocol::BlendMode::Average) { // a grey ramp: a radiograph
            protocol::SetTransferFunction ramp;
            ramp.kind = protocol::TfKind::Points;
            ramp.shadingSource = protocol::ShadingSource::Message;
            ramp.points = {{protocol::Placement::Fraction, 0, {0, 0, 0, 0}},
                           {protocol::Placement::Fraction, 1, {1, 1, 1, 1}}};
            c.setTransferFunction(ramp);
        }
        c.setCamera(orbitCamera(v, 40.0 * id, id));
        ++id;
        c.requestFrame();
        out.push_back(c.nextFrame());
    }
    return out;
}

/// The first `passes` refined frames at rest of one view under an error bound at rest, early
/// termination off: the pass at the session's step, then at half of it, and so on (72^2 frames
/// are too small for the sparse check that would start at half the step).
std::vector<client::ReceivedFrame> passesAtRest(const client::ClientConfig& config,
                                                const std::string& volume, const std::string& tf,
                                                std::size_t passes) {
    client::Client c(config);
    const auto v = c.openVolume(volume);
    c.setTransferFunction(preset(tf));
    protocol::RenderOptions o = smallCpuFrames(72);
    o.codec = protocol::Codec::Raw;
    o.quality = protocol::Quality::Adaptive;
    o.stepVoxels = 2;
    o.techniques &= ~protocol::kTechEarlyTermination;
    c.setRenderOptions(o);
    c.setFrameBudget({0, protocol::kMaxRestPsnrDb});
    c.requestFrame(protocol::FrameMode::ContinuousOn);
    c.setCamera(orbitCamera(v, 40, 1));
    std::vector<client::ReceivedFrame> out;
    while (out.size() < passes) {
        client::ReceivedFrame f = c.nextFrame();
        if (f.header.refined) out.push_back(std::move(f));
    }
    return out;
}

/// Largest difference of two 8-bit frames, in levels.
int maxLevels(const client::ReceivedFrame& a, const client::ReceivedFrame& b) {
    if (a.rgba.size() != b.rgba.size()) return 256;
    int m = 0;
    for (std::size_t i = 0; i < a.rgba.size(); ++i)
        m = std::max(m, std::abs(int(a.rgba[i]) - int(b.rgba[i])));
    return m;
}

class MpiDaemon : public ::testing::Test {
  protected:
    void SetUp() override {
#ifndef BC_MPIEXEC
        if (bc::test::dataRequired()) FAIL() << "built without MPI (libopenmpi-dev)";
        GTEST_SKIP() << "built without MPI (libopenmpi-dev)";
#endif
    }

    /// A config of `volumes` (TOML [[volume]] tables) with a 1 MiB host budget: every volume
    /// is larger than it, so each rank (and the one process) draws in batches.
    std::string writeConfig(const std::string& name, const std::string& volumes,
                            const std::string& frames = "") {
        const std::string path = dir.file(name);
        std::ofstream(path) << "[server]\nlisten = \"127.0.0.1:0\"\nweb = \"\"\nstore_dir = \""
                            << dir.path().string() << "\"\n[budgets]\nhost_mb = 1\n"
                            << (frames.empty() ? "" : "[frames]\n" + frames + "\n") << volumes;
        return path;
    }

    /// Ingests the real scan cthead and headsq into the scratch folder: their [[volume]]
    /// tables, or "" when the data is missing.
    std::string realScans() {
        std::string volumes;
        struct Scan {
            const char *name, *file, *args;
        };
        for (const Scan& s :
             {Scan{"cthead", "stanford_cthead_256x256x113_uint16.raw",
                   "--dims 256,256,113 --type u16 --spacing 1,1,2 --endian little"},
              Scan{"headsq", "vtk_headsq_quarter_64x64x93_uint16.raw",
                   "--dims 64,64,93 --type u16 --spacing 3.2,3.2,1.5 --endian little"}}) {
            if (!bc::test::haveData(s.file)) {
                bc::test::missingData(std::string("scan ") + s.name);
                continue;
            }
            const std::string store = dir.file(std::string(s.name) + ".bcs");
            const auto r = bc::test::runCommand(std::string(BC_BRICKCAST_EXE) + " ingest " +
                                                bc::test::dataPath(s.file) + " " + s.args +
                                                " --brick 32 -q -o " + store);
            EXPECT_EQ(r.exitCode, 0) << r.text;
            volumes +=
                "[[volume]]\nname = \"" + std::string(s.name) + "\"\nstore = \"" + store + "\"\n";
        }
        return volumes;
    }

    struct Case {
        std::string volume, tf;
    };

    using Frames = std::vector<client::ReceivedFrame>;
    /// `fly`'s frames from one brickcastd process, then from a job of two ranks, both serving a
    /// generated 96^3 phantom "p"; empty (a failure recorded) when a job does not start.
    std::pair<Frames, Frames>
    oneAndTwoRanks(const std::function<Frames(const client::ClientConfig&)>& fly) {
        std::pair<Frames, Frames> out;
#ifdef BC_MPIEXEC
        const std::string config = writeConfig(
            "c.toml", "[[volume]]\nname = \"p\"\ngenerate = \"phantom\"\ndims = [96, 96, 96]\n");
        auto launch = [&](const char* ranks, const std::string& portFile) {
            return startJob(dir,
                            {"-np", ranks, BC_BRICKCASTD_EXE, "--config", config, "--port-file",
                             portFile, "--quiet"},
                            portFile, 120);
        };
        Job one = launch("1", dir.file("one.port"));
        JobGuard oneGuard{one};
        if (!one.started) {
            ADD_FAILURE() << one.text();
            return out;
        }
        Frames want = fly(one.client);
        Job job = launch("2", dir.file("ranks.port"));
        JobGuard guard{job};
        if (!job.started) {
            ADD_FAILURE() << job.text();
            return out;
        }
        out = {std::move(want), fly(job.client)};
#endif
        return out;
    }

    /// The GPU raycaster's frames over `ranks` (every case): on llvmpipe in CI, where every
    /// rank makes its own GL context.
    void expectRanksServeTheOneProcessGpuFrames(int ranks);

    /// Every frame of an orbit of each case, drawn by one brickcastd process and by jobs of
    /// each rank count, early termination off and on; then SIGTERM to rank 0 ends each job.
    /// llvmpipe draws with one thread per process (LP_NUM_THREADS): up to 4 ranks share 2
    /// cores, and its threads would only contend (the images do not depend on it).
    void expectRanksServeTheOneProcessFrames(const std::string& config, protocol::Renderer renderer,
                                             const std::vector<Case>& cases,
                                             const std::vector<int>& rankCounts) {
#ifdef BC_MPIEXEC
        // One process first: it ingests the generated volumes the jobs then reuse.
        const std::string onePort = dir.file("one.port");
        Job one = startJob(dir,
                           {"-x", "LP_NUM_THREADS=1", "-np", "1", BC_BRICKCASTD_EXE, "--config",
                            config, "--port-file", onePort, "--quiet"},
                           onePort, 120);
        JobGuard oneGuard{one};
        ASSERT_TRUE(one.started) << one.text();
        std::map<std::string, std::vector<client::ReceivedFrame>> reference[2];
        for (const Case& c : cases)
            for (bool ert : {false, true})
                reference[ert][c.volume] = orbit(one.client, c.volume, c.tf, renderer, ert, 6);
        for (int ranks : rankCounts) {
            const std::string port = dir.file("ranks" + std::to_string(ranks) + ".port");
            Job job =
                startJob(dir,
                         {"-x", "LP_NUM_THREADS=1", "-np", std::to_string(ranks), BC_BRICKCASTD_EXE,
                          "--config", config, "--port-file", port, "--metrics", "127.0.0.1:0",
                          "--metrics-port-file", port + ".metrics", "--quiet"},
                         port, 120);
            JobGuard guard{job};
            ASSERT_TRUE(job.started) << job.text();
            for (const Case& c : cases)
                for (bool ert : {false, true}) {
                    const auto frames = orbit(job.client, c.volume, c.tf, renderer, ert, 6);
                    for (std::size_t i = 0; i < frames.size(); ++i) {
                        const auto& want = reference[ert][c.volume][i];
                        // ERT off: the same samples, composited in another association (float
                        // rounding under 1e-6: at most one 8-bit level); on: each rank stops
                        // its own segment, within early termination's bound (SCALEOUT.md).
                        EXPECT_LE(maxLevels(frames[i], want), ert ? 1 + int(1.25 * 0.01 * 255) : 1)
                            << ranks << " ranks, " << c.volume << " frame " << i
                            << (ert ? ", ERT on" : ", ERT off");
                        if (!ert) {
                            EXPECT_EQ(frames[i].header.samples, want.header.samples)
                                << ranks << " ranks, " << c.volume << " frame " << i;
                        }
                    }
                }
            // Every rank's share is counted.
            std::uint16_t metricsPort = 0;
            std::ifstream(port + ".metrics") >> metricsPort;
            const std::string text = scrape(metricsPort, "GET /metrics HTTP/1.0\r\n\r\n");
            EXPECT_EQ(sampleOf(text, "brickcast_cluster_ranks"), double(ranks)) << text;
            EXPECT_GT(sampleOf(text, "brickcast_cluster_slices_total"), 0.0);
            EXPECT_GT(sampleOf(text, "brickcast_cluster_composited_bytes_total"), 0.0);
            for (int r = 0; r < ranks; ++r)
                EXPECT_GT(sampleOf(text, "brickcast_cluster_rank_samples_total{rank=\"" +
                                             std::to_string(r) + "\"}"),
                          0.0)
                    << "rank " << r;
            EXPECT_EQ(sampleOf(text, "brickcast_cluster_failures_total"), 0.0);
            // SIGTERM to rank 0 drains it and stops every rank.
            const pid_t root = rankPid(job, 0);
            ASSERT_GT(root, 0);
            ASSERT_EQ(::kill(root, SIGTERM), 0);
            const auto status = waitForJob(job, 30);
            ASSERT_TRUE(status.has_value()) << "the job did not end after SIGTERM to rank 0\n"
                                            << job.text();
            EXPECT_TRUE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << job.text();
        }
#endif
    }

    TempDir dir;
};

/// The volumes every frame test serves: the real scans, a generated vessel tree of 7 MiB (a
/// 1 MiB host budget per rank) and a phantom of one brick (fewer bricks than ranks).
const char* kGenerated =
    "[[volume]]\nname = \"vessels\"\ngenerate = \"vessels\"\n"
    "dims = [192, 192, 192]\n"
    "[[volume]]\nname = \"tiny\"\ngenerate = \"phantom\"\ndims = [24, 24, 24]\n";

TEST_F(MpiDaemon, TwoAndFourRanksServeTheOneProcessFrames) {
    const std::string volumes = realScans() + kGenerated;
    std::vector<Case> cases{{"vessels", "vessels"}, {"tiny", "ct-skin"}};
    if (volumes.find("\"cthead\"") != std::string::npos) cases.push_back({"cthead", "ct-bone"});
    if (volumes.find("\"headsq\"") != std::string::npos) cases.push_back({"headsq", "ct-skin"});
    expectRanksServeTheOneProcessFrames(writeConfig("c.toml", volumes),
                                        protocol::Renderer::CpuRaycaster, cases, {2, 4});
}

void MpiDaemon::expectRanksServeTheOneProcessGpuFrames(int ranks) {
    const std::string volumes = realScans() + kGenerated;
    std::vector<Case> cases{{"tiny", "ct-skin"}, {"vessels", "vessels"}};
    if (volumes.find("\"cthead\"") != std::string::npos) cases.push_back({"cthead", "ct-skin"});
    if (volumes.find("\"headsq\"") != std::string::npos) cases.push_back({"headsq", "ct-bone"});
    expectRanksServeTheOneProcessFrames(writeConfig("c.toml", volumes),
                                        protocol::Renderer::GpuRaycaster, cases, {ranks});
}

TEST_F(MpiDaemon, TwoRanksServeTheOneProcessGpuFrames) {
    expectRanksServeTheOneProcessGpuFrames(2);
}

// Four ranks of llvmpipe on a 2-core machine take minutes: label "slow" (the CPU frames cover
// four ranks in the fast suite).
using MpiDaemonSlow = MpiDaemon;
TEST_F(MpiDaemonSlow, FourRanksServeTheOneProcessGpuFrames) {
    expectRanksServeTheOneProcessGpuFrames(4);
}

// A session's modes and cuts across two ranks: the projections combine by their mode, the
// isosurface over front to back, and rank 0 maps the combined values through the table.
TEST_F(MpiDaemon, TwoRanksServeTheOneProcessFramesOfEachModeCut) {
    const auto [want, got] = oneAndTwoRanks([](const auto& c) { return cutModes(c, "p"); });
    for (std::size_t i = 0; i < std::min(want.size(), got.size()); ++i) {
        EXPECT_LE(maxLevels(got[i], want[i]), 1) << "mode " << i;
        EXPECT_GT(std::count_if(want[i].rgba.begin(), want[i].rgba.end(),
                                [](std::uint8_t b) { return b > 0; }),
                  100)
            << "mode " << i << ": the frame shows (nearly) nothing";
    }
}

// Under an error bound at rest, each refinement pass halves the step: the worker ranks draw
// their parts at the pass's step, as rank 0 draws its own, so that every pass is the one
// process's pass.
TEST_F(MpiDaemon, RefinedPassesAtRestDrawEveryRankAtThePassStep) {
    const auto [want, got] =
        oneAndTwoRanks([](const auto& c) { return passesAtRest(c, "p", "ct-skin", 2); });
    if (want.size() < 2 || got.size() != want.size()) return; // a job did not start
    for (std::size_t i = 0; i < want.size(); ++i) {
        std::printf("[mpi] pass %zu at rest: %llu samples over 2 ranks, %llu in one process\n", i,
                    static_cast<unsigned long long>(got[i].header.samples),
                    static_cast<unsigned long long>(want[i].header.samples));
        EXPECT_EQ(got[i].header.samples, want[i].header.samples) << "pass " << i;
        EXPECT_LE(maxLevels(got[i], want[i]), 1) << "pass " << i;
    }
    // The second pass took more samples than the first (the step halved).
    EXPECT_GT(want[1].header.samples, want[0].header.samples);
}

TEST_F(MpiDaemon, ARankKilledOrStoppedFailsItsFramesWithinTheTimeout) {
#ifdef BC_MPIEXEC
    const std::string config = writeConfig(
        "c.toml", "[[volume]]\nname = \"p\"\ngenerate = \"phantom\"\ndims = [64, 64, 64]\n",
        "cluster_timeout_ms = 2000");
    for (int signal : {SIGKILL, SIGSTOP}) {
        const std::string port = dir.file("port" + std::to_string(signal));
        // --enable-recovery: mpirun keeps the other ranks when one dies (without it, it ends
        // the job).
        Job job = startJob(dir,
                           {"--enable-recovery", "-np", "3", BC_BRICKCASTD_EXE, "--config", config,
                            "--port-file", port},
                           port);
        JobGuard guard{job};
        ASSERT_TRUE(job.started) << job.text();
        client::Client c(job.client);
        const auto v = c.openVolume("p");
        c.setRenderOptions(smallCpuFrames(64));
        c.setCamera(orbitCamera(v, 30, 1));
        c.requestFrame();
        c.nextFrame();
        const pid_t victim = rankPid(job, 2);
        ASSERT_GT(victim, 0);
        // Rank 2 killed or stopped between frames (a kill timed to land mid-frame races the
        // frame: this one takes about 0.3 s a part). In this view rank 1 needs none of rank
        // 2's pixels: it draws and composites its band and goes back to waiting for orders,
        // so the SIGTERM below must end a rank that is alive and listening as well as the
        // one at fault (under --enable-recovery MPI_Abort ends only its caller).
        ASSERT_EQ(::kill(victim, signal), 0);
        protocol::RenderOptions heavy = smallCpuFrames(1024);
        heavy.stepVoxels = 0.05f;
        heavy.techniques &= ~protocol::kTechEarlyTermination;
        c.setRenderOptions(heavy);
        c.setCamera(orbitCamera(v, 60, 2));
        c.requestFrame();
        for (int i = 0; i < 2; ++i) {
            const auto start = std::chrono::steady_clock::now();
            if (i == 1) { // the next frame, after the cluster failed
                c.setRenderOptions(smallCpuFrames(64));
                c.setCamera(orbitCamera(v, 90, 3));
                c.requestFrame();
            }
            try {
                c.nextFrame();
                ADD_FAILURE() << "a frame was drawn without rank 2 (frame " << i << ")";
            } catch (const client::ServerError& e) {
                EXPECT_EQ(e.code(), protocol::ErrorCode::RenderFailed);
                // Named once, though it owes both a part and the composite's replies.
                EXPECT_NE(std::string(e.what()).find("rank 2 did not answer"), std::string::npos)
                    << e.what();
            }
            // The frame fails within the timeout (2 s); the next at once.
            const double s =
                std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
            EXPECT_LT(s, i == 0 ? 10.0 : 1.0) << "frame " << i;
        }
        // The front end still answers what needs no rank.
        EXPECT_EQ(c.listVolumes().size(), 1u);
        const pid_t root = rankPid(job, 0);
        ASSERT_GT(root, 0);
        // SIGTERM to rank 0 ends it and rank 1, which hears rank 0's quit (it does not wait
        // out its minute of silence). The rank at fault is the launcher's to end: after
        // MPI_Abort, Open MPI 4.1's mpirun --enable-recovery sometimes leaves a stopped rank
        // stopped (JobGuard ends it).
        ASSERT_EQ(::kill(root, SIGTERM), 0);
        EXPECT_TRUE(ranksEnd(job, {0, 1}, 30))
            << "ranks 0 and 1 did not end after SIGTERM to rank 0\n"
            << job.text();
        EXPECT_NE(job.text().find("cluster"), std::string::npos) << job.text();
        EXPECT_NE(job.text().find("rank 1: rank 0 ends the job"), std::string::npos) << job.text();
    }
#endif
}

TEST_F(MpiDaemon, RanksOfDifferentConfigsRefuseToStartNamingTheRank) {
#ifdef BC_MPIEXEC
    const std::string volume =
        "[[volume]]\nname = \"p\"\ngenerate = \"phantom\"\ndims = [32, 32, 32]\n";
    const std::string a = writeConfig("a.toml", volume),
                      b = writeConfig("b.toml", volume, "rest_ms = 300");
    Job job = startJob(dir,
                       {"-np", "1", BC_BRICKCASTD_EXE, "--config", a, ":", "-np", "1",
                        BC_BRICKCASTD_EXE, "--config", b},
                       "");
    JobGuard guard{job};
    const auto status = waitForJob(job, 60);
    ASSERT_TRUE(status.has_value()) << "the job hung\n" << job.text();
    EXPECT_FALSE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << job.text();
    EXPECT_NE(job.text().find("rank 1: its config differs from rank 0's"), std::string::npos)
        << job.text();
#endif
}

TEST_F(MpiDaemon, ARankThatCannotOpenItsStoreRefusesTheStartNamingIt) {
#ifdef BC_MPIEXEC
    // The same config text in two folders; its store path is relative to the config's folder,
    // and only the first has the store (as if the second node did not mount the share).
    const std::string store = dir.file("p.bcs");
    const auto r = bc::test::runCommand(std::string(BC_BRICKCAST_EXE) +
                                        " ingest synth:phantom --dims 40,40,40 -q -o " + store);
    ASSERT_EQ(r.exitCode, 0) << r.text;
    const std::string text =
        "[server]\nlisten = \"127.0.0.1:0\"\nweb = \"\"\n[[volume]]\nname = \"p\"\nstore = "
        "\"p.bcs\"\n";
    std::filesystem::create_directories(dir.file("elsewhere"));
    std::ofstream(dir.file("a.toml")) << text;
    std::ofstream(dir.file("elsewhere/a.toml")) << text;
    Job job = startJob(dir,
                       {"-np", "1", BC_BRICKCASTD_EXE, "--config", dir.file("a.toml"), ":", "-np",
                        "1", BC_BRICKCASTD_EXE, "--config", dir.file("elsewhere/a.toml")},
                       "");
    JobGuard guard{job};
    const auto status = waitForJob(job, 60);
    ASSERT_TRUE(status.has_value()) << "the job hung\n" << job.text();
    EXPECT_FALSE(WIFEXITED(*status) && WEXITSTATUS(*status) == 0) << job.text();
    EXPECT_NE(job.text().find("rank 1: "), std::string::npos) << job.text();
    EXPECT_NE(job.text().find("elsewhere/p.bcs"), std::string::npos) << job.text();
#endif
}

} // namespace
} // namespace bc::server::test

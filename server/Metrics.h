#pragma once
// What brickcastd counts, in two forms: the Prometheus text exposition format (version
// 0.0.4, what GET /metrics on the metrics address serves and what operators scrape) and the
// flat (name, value) pairs of the protocol's Stats message. A MetricSet is built fresh for
// each scrape from the live counters (RenderService::collect, Catalog caches, sessions); it
// is a value, not a registry, so nothing in the daemon locks for longer than a copy.
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

namespace bc::server {

/// A histogram with fixed upper bucket bounds (ascending; +Inf is implied). Not thread-safe:
/// its owner guards it.
class Histogram {
  public:
    /// @throw std::invalid_argument when `bounds` is empty, not ascending or not finite.
    explicit Histogram(std::vector<double> bounds);
    void observe(double value);
    const std::vector<double>& bounds() const { return mBounds; }
    /// Per bucket, not cumulative; one more than bounds() (the +Inf bucket last).
    const std::vector<std::uint64_t>& counts() const { return mCounts; }
    double sum() const { return mSum; }
    std::uint64_t count() const { return mCount; }
    /// The q-quantile (0..1) estimated as Prometheus' histogram_quantile does: linear within
    /// the bucket holding it, the highest finite bound for the +Inf bucket; NaN when empty.
    double quantile(double q) const;

    /// Bounds 1, 2, 5, 10, 20, ... up to `max` (a 1-2-5 series).
    static std::vector<double> series125(double min, double max);
    /// Bounds min, min * factor, ... up to max.
    static std::vector<double> geometric(double min, double max, double factor);

  private:
    std::vector<double> mBounds;
    std::vector<std::uint64_t> mCounts;
    double mSum = 0.0;
    std::uint64_t mCount = 0;
};

class MetricSet {
  public:
    enum class Type { Counter, Gauge, Histogram };

    /// `name` without the "brickcast_" prefix ([a-z_][a-z0-9_]*; counters end in _total);
    /// `labels` as key=value pairs, values escaped on output. @throw std::invalid_argument on
    /// a bad name, or a name already added with another type or help.
    void counter(const std::string& name, const std::string& help, double value,
                 std::vector<std::pair<std::string, std::string>> labels = {});
    void gauge(const std::string& name, const std::string& help, double value,
               std::vector<std::pair<std::string, std::string>> labels = {});
    void histogram(const std::string& name, const std::string& help, const Histogram& h,
                   std::vector<std::pair<std::string, std::string>> labels = {});

    /// Families in the order first added, each with # HELP and # TYPE once.
    std::string prometheusText() const;
    /// name{labels} -> value; a histogram gives _count, _sum, _p50 and _p99. Names longer
    /// than `maxNameBytes` are cut (the protocol's limit).
    std::vector<std::pair<std::string, double>> statCounters(std::size_t maxNameBytes) const;
    /// The value of a counter or gauge sample (tests). @throw std::out_of_range when absent.
    double value(const std::string& name,
                 const std::vector<std::pair<std::string, std::string>>& labels = {}) const;

  private:
    struct Sample {
        std::vector<std::pair<std::string, std::string>> labels;
        double value = 0.0;
        std::vector<double> bounds;         ///< histograms
        std::vector<std::uint64_t> buckets; ///< histograms, per bucket
        std::uint64_t count = 0;
        double p50 = 0.0, p99 = 0.0;
    };
    struct Family {
        std::string name, help;
        Type type;
        std::vector<Sample> samples;
    };
    Family& family(const std::string& name, const std::string& help, Type type);
    std::vector<Family> mFamilies;
};

} // namespace bc::server

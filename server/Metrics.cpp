#include "server/Metrics.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <limits>
#include <stdexcept>

namespace bc::server {
namespace {

constexpr const char* kPrefix = "brickcast_";

bool validName(const std::string& name) {
    if (name.empty() || !(std::islower((unsigned char)name[0]) || name[0] == '_')) return false;
    return std::all_of(name.begin(), name.end(), [](unsigned char c) {
        return std::islower(c) || std::isdigit(c) || c == '_';
    });
}

/// Prometheus' float text: integers without an exponent, NaN and infinities spelled out.
std::string number(double v) {
    if (std::isnan(v)) return "NaN";
    if (std::isinf(v)) return v > 0 ? "+Inf" : "-Inf";
    char b[40];
    if (v == std::floor(v) && std::abs(v) < 1e15)
        std::snprintf(b, sizeof b, "%.0f", v);
    else
        std::snprintf(b, sizeof b, "%.17g", v);
    return b;
}

std::string escapeLabel(const std::string& v) {
    std::string out;
    for (char c : v) {
        if (c == '\\')
            out += "\\\\";
        else if (c == '"')
            out += "\\\"";
        else if (c == '\n')
            out += "\\n";
        else
            out += c;
    }
    return out;
}

std::string escapeHelp(const std::string& v) {
    std::string out;
    for (char c : v) {
        if (c == '\\')
            out += "\\\\";
        else if (c == '\n')
            out += "\\n";
        else
            out += c;
    }
    return out;
}

std::string labelText(const std::vector<std::pair<std::string, std::string>>& labels,
                      const std::string& extraKey = "", const std::string& extraValue = "") {
    if (labels.empty() && extraKey.empty()) return "";
    std::string out = "{";
    bool first = true;
    for (const auto& [k, v] : labels) {
        out += (first ? "" : ",") + k + "=\"" + escapeLabel(v) + "\"";
        first = false;
    }
    if (!extraKey.empty()) out += (first ? "" : ",") + extraKey + "=\"" + extraValue + "\"";
    return out + "}";
}

void checkLabels(const std::vector<std::pair<std::string, std::string>>& labels) {
    for (const auto& [k, v] : labels)
        if (!validName(k) || k == "le")
            throw std::invalid_argument("metric label '" + k + "' is not a valid label name");
}

} // namespace

Histogram::Histogram(std::vector<double> bounds) : mBounds(std::move(bounds)) {
    if (mBounds.empty()) throw std::invalid_argument("histogram: no bucket bounds");
    for (std::size_t i = 0; i < mBounds.size(); ++i)
        if (!std::isfinite(mBounds[i]) || (i > 0 && !(mBounds[i] > mBounds[i - 1])))
            throw std::invalid_argument("histogram: bounds must be finite and ascending");
    mCounts.assign(mBounds.size() + 1, 0);
}

void Histogram::observe(double value) {
    if (std::isnan(value)) return;
    const auto it = std::lower_bound(mBounds.begin(), mBounds.end(), value); // le: value <= bound
    ++mCounts[std::size_t(it - mBounds.begin())];
    mSum += value;
    ++mCount;
}

double Histogram::quantile(double q) const {
    if (mCount == 0) return std::numeric_limits<double>::quiet_NaN();
    const double rank = std::clamp(q, 0.0, 1.0) * double(mCount);
    std::uint64_t below = 0;
    for (std::size_t i = 0; i < mCounts.size(); ++i) {
        const std::uint64_t in = mCounts[i];
        if (double(below + in) >= rank && in > 0) {
            if (i == mBounds.size()) return mBounds.back(); // the +Inf bucket
            const double lo = i == 0 ? std::min(0.0, mBounds[0]) : mBounds[i - 1];
            return lo + (mBounds[i] - lo) * (rank - double(below)) / double(in);
        }
        below += in;
    }
    return mBounds.back();
}

std::vector<double> Histogram::series125(double min, double max) {
    std::vector<double> out;
    for (double decade = min; decade <= max; decade *= 10)
        for (double m : {1.0, 2.0, 5.0})
            if (decade * m <= max * (1 + 1e-12)) out.push_back(decade * m);
    return out;
}

std::vector<double> Histogram::geometric(double min, double max, double factor) {
    std::vector<double> out;
    for (double b = min; b <= max * (1 + 1e-12); b *= factor)
        out.push_back(b);
    return out;
}

MetricSet::Family& MetricSet::family(const std::string& name, const std::string& help, Type type) {
    if (!validName(name)) throw std::invalid_argument("metric name '" + name + "' is not valid");
    for (Family& f : mFamilies)
        if (f.name == name) {
            if (f.type != type || f.help != help)
                throw std::invalid_argument("metric '" + name + "' added twice differently");
            return f;
        }
    mFamilies.push_back({name, help, type, {}});
    return mFamilies.back();
}

void MetricSet::counter(const std::string& name, const std::string& help, double value,
                        std::vector<std::pair<std::string, std::string>> labels) {
    if (!name.ends_with("_total"))
        throw std::invalid_argument("counter '" + name + "' must end in _total");
    checkLabels(labels);
    Sample sample;
    sample.labels = std::move(labels);
    sample.value = value;
    family(name, help, Type::Counter).samples.push_back(std::move(sample));
}

void MetricSet::gauge(const std::string& name, const std::string& help, double value,
                      std::vector<std::pair<std::string, std::string>> labels) {
    checkLabels(labels);
    Sample sample;
    sample.labels = std::move(labels);
    sample.value = value;
    family(name, help, Type::Gauge).samples.push_back(std::move(sample));
}

void MetricSet::histogram(const std::string& name, const std::string& help, const Histogram& h,
                          std::vector<std::pair<std::string, std::string>> labels) {
    checkLabels(labels);
    Sample s{std::move(labels), h.sum(),         h.bounds(),      h.counts(),
             h.count(),         h.quantile(0.5), h.quantile(0.99)};
    family(name, help, Type::Histogram).samples.push_back(std::move(s));
}

std::string MetricSet::prometheusText() const {
    std::string out;
    for (const Family& f : mFamilies) {
        const std::string full = kPrefix + f.name;
        out += "# HELP " + full + " " + escapeHelp(f.help) + "\n";
        out += "# TYPE " + full + " " +
               (f.type == Type::Counter ? "counter"
                : f.type == Type::Gauge ? "gauge"
                                        : "histogram") +
               "\n";
        for (const Sample& s : f.samples) {
            if (f.type != Type::Histogram) {
                out += full + labelText(s.labels) + " " + number(s.value) + "\n";
                continue;
            }
            std::uint64_t cumulative = 0;
            for (std::size_t i = 0; i < s.buckets.size(); ++i) {
                cumulative += s.buckets[i];
                const std::string le = i < s.bounds.size() ? number(s.bounds[i]) : "+Inf";
                out += full + "_bucket" + labelText(s.labels, "le", le) + " " +
                       std::to_string(cumulative) + "\n";
            }
            out += full + "_sum" + labelText(s.labels) + " " + number(s.value) + "\n";
            out += full + "_count" + labelText(s.labels) + " " + std::to_string(s.count) + "\n";
        }
    }
    return out;
}

std::vector<std::pair<std::string, double>>
MetricSet::statCounters(std::size_t maxNameBytes) const {
    std::vector<std::pair<std::string, double>> out;
    auto add = [&](std::string name, double v) {
        if (name.size() > maxNameBytes) name.resize(maxNameBytes);
        out.emplace_back(std::move(name), v);
    };
    for (const Family& f : mFamilies)
        for (const Sample& s : f.samples) {
            const std::string labels = labelText(s.labels);
            if (f.type != Type::Histogram) {
                add(f.name + labels, s.value);
                continue;
            }
            add(f.name + "_count" + labels, double(s.count));
            add(f.name + "_sum" + labels, s.value);
            add(f.name + "_p50" + labels, s.p50);
            add(f.name + "_p99" + labels, s.p99);
        }
    return out;
}

double MetricSet::value(const std::string& name,
                        const std::vector<std::pair<std::string, std::string>>& labels) const {
    for (const Family& f : mFamilies)
        if (f.name == name)
            for (const Sample& s : f.samples)
                if (s.labels == labels) return s.value;
    throw std::out_of_range("no metric " + name + labelText(labels));
}

} // namespace bc::server

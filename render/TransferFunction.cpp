#include "render/TransferFunction.h"

#include "brickstore/BrickStore.h"
#include "render/Error.h"
#include "render/detail/TfPresets.h"

#include <nlohmann/json.hpp>

#include <algorithm>
#include <bit>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <limits>
#include <stdexcept>

namespace bc::render {

namespace {

using Json = nlohmann::json;

std::string formatNumber(double v) {
    char text[32];
    std::snprintf(text, sizeof text, "%.10g", v);
    return text;
}

[[noreturn]] void fail(const std::string& source, const std::string& field,
                       const std::string& why) {
    throw RenderInputError(source, field, why);
}

Json parseJson(const std::string& text, const std::string& source) {
    try {
        return Json::parse(text);
    } catch (const Json::parse_error& e) {
        fail(source, "(json)", std::string(e.what()) + " (byte " + std::to_string(e.byte) + ")");
    } catch (const Json::out_of_range& e) { // 1e999: the parser refuses infinities itself
        fail(source, "(json)", std::string(e.what()) + " (not a finite number)");
    }
}

double finiteNumber(const Json& j, const std::string& source, const std::string& field) {
    if (!j.is_number()) fail(source, field, std::string("expected a number, got ") + j.type_name());
    const double v = j.get<double>();
    if (!std::isfinite(v)) fail(source, field, "not a finite number");
    return v;
}

const char* placementKey(Placement p) {
    switch (p) {
    case Placement::Value:
        return "value";
    case Placement::Fraction:
        return "fraction";
    case Placement::Percentile:
        return "percentile";
    }
    return "value";
}

/// Native value of `spec` placed for a volume; `field` names the point ("points[3]").
ControlPoint place(const PointSpec& spec, const VolumeValueStats& stats, const std::string& source,
                   const std::string& field) {
    const std::string f = field + "." + placementKey(spec.placement);
    const double x = spec.position;
    if (!std::isfinite(x)) fail(source, f, "not a finite number");
    for (std::size_t c = 0; c < 4; ++c) {
        const double v = spec.rgba[c];
        const std::string fc = field + ".rgba[" + std::to_string(c) + "]";
        if (!std::isfinite(v)) fail(source, fc, "not a finite number");
        if (!(v >= 0.0 && v <= 1.0)) fail(source, fc, formatNumber(v) + " outside [0, 1]");
    }
    ControlPoint p;
    p.rgba = spec.rgba;
    switch (spec.placement) {
    case Placement::Value:
        p.value = x;
        break;
    case Placement::Fraction:
        if (!(x >= 0.0 && x <= 1.0)) fail(source, f, formatNumber(x) + " outside [0, 1]");
        p.value = stats.valueMin + x * (stats.valueMax - stats.valueMin);
        break;
    case Placement::Percentile:
        if (!(x >= 0.0 && x <= 100.0)) fail(source, f, formatNumber(x) + " outside [0, 100]");
        try {
            p.value = stats.percentile(x);
        } catch (const std::invalid_argument& e) {
            fail(source, f, std::string("no percentile: ") + e.what());
        }
        break;
    }
    return p;
}

std::array<float, 4> parseRgba(const Json& j, const std::string& source, const std::string& field) {
    if (!j.is_array() || j.size() != 4)
        fail(source, field, "expected an array of 4 numbers in [0, 1]");
    std::array<float, 4> rgba{};
    for (std::size_t i = 0; i < 4; ++i) {
        const std::string f = field + "[" + std::to_string(i) + "]";
        const double v = finiteNumber(j[i], source, f);
        if (!(v >= 0.0 && v <= 1.0)) fail(source, f, formatNumber(v) + " outside [0, 1]");
        rgba[i] = float(v);
    }
    return rgba;
}

PointSpec parsePoint(const Json& j, const std::string& source, const std::string& field) {
    if (!j.is_object())
        fail(source, field, std::string("expected an object, got ") + j.type_name());
    std::string placement;
    for (auto it = j.begin(); it != j.end(); ++it) {
        const std::string& key = it.key();
        if (key == "rgba") continue;
        if (key != "value" && key != "fraction" && key != "percentile")
            fail(source, field + "." + key,
                 "unknown key (expected value, fraction, percentile, rgba)");
        if (!placement.empty())
            fail(source, field,
                 "placed twice (" + placement + " and " + key +
                     "): give exactly one of value, fraction, percentile");
        placement = key;
    }
    if (placement.empty())
        fail(source, field, "not placed: give exactly one of value, fraction, percentile");
    if (!j.contains("rgba")) fail(source, field + ".rgba", "missing");
    PointSpec p;
    p.placement = placement == "value"      ? Placement::Value
                  : placement == "fraction" ? Placement::Fraction
                                            : Placement::Percentile;
    p.rgba = parseRgba(j["rgba"], source, field + ".rgba");
    p.position = finiteNumber(j[placement], source, field + "." + placement);
    return p;
}

std::vector<PointSpec> parsePoints(const Json& doc, const std::string& source) {
    if (!doc.contains("points")) fail(source, "points", "missing");
    const Json& points = doc["points"];
    if (!points.is_array())
        fail(source, "points", std::string("expected an array, got ") + points.type_name());
    if (points.size() > TransferFunction::kMaxPoints)
        fail(source, "points",
             std::to_string(points.size()) + " points, more than " +
                 std::to_string(TransferFunction::kMaxPoints));
    std::vector<PointSpec> out;
    for (std::size_t i = 0; i < points.size(); ++i)
        out.push_back(parsePoint(points[i], source, "points[" + std::to_string(i) + "]"));
    return out;
}

/// 64-bit FNV-1a over `bytes`, continuing from `h`.
std::uint64_t fnv1a(std::uint64_t h, const void* bytes, std::size_t n) {
    const auto* p = static_cast<const unsigned char*>(bytes);
    for (std::size_t i = 0; i < n; ++i)
        h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

void checkTopLevelKeys(const Json& doc, const std::string& source) {
    for (auto it = doc.begin(); it != doc.end(); ++it) {
        const std::string& key = it.key();
        if (key == "points") continue;
        if (key != "name" && key != "description" && key != "shading")
            fail(source, key, "unknown key (expected name, description, shading, points)");
        if (key == "shading" ? !it->is_boolean() : !it->is_string())
            fail(source, key,
                 std::string("expected a ") + (key == "shading" ? "boolean" : "string") + ", got " +
                     it->type_name());
    }
}

void checkStats(const VolumeValueStats& stats) {
    if (!std::isfinite(stats.valueMin) || !std::isfinite(stats.valueMax) ||
        stats.valueMin > stats.valueMax)
        throw std::invalid_argument("VolumeValueStats: value range [" +
                                    formatNumber(stats.valueMin) + ", " +
                                    formatNumber(stats.valueMax) + "] is not a finite interval");
}

std::string presetList() {
    std::string list;
    for (const auto& name : TransferFunction::presetNames())
        list += (list.empty() ? "" : ", ") + name;
    return list;
}

} // namespace

// ---- VolumeValueStats -------------------------------------------------------------------

VolumeValueStats VolumeValueStats::fromStore(const brickstore::StoreInfo& info) {
    return VolumeValueStats{info.valueMin, info.valueMax, info.histogram};
}

std::size_t VolumeValueStats::modeBin() const {
    if (histogram.empty()) throw std::invalid_argument("the volume's histogram is empty");
    return std::size_t(std::max_element(histogram.begin(), histogram.end()) - histogram.begin());
}

double VolumeValueStats::percentile(double percent) const {
    if (!(percent >= 0.0 && percent <= 100.0))
        throw std::invalid_argument("percentile " + formatNumber(percent) + " outside [0, 100]");
    // Voxels above the most populated bin (the background, as a rule); all when none are.
    std::size_t first = modeBin() + 1;
    double total = 0.0;
    for (std::size_t i = first; i < histogram.size(); ++i)
        total += double(histogram[i]);
    if (total == 0.0) {
        first = 0;
        for (const auto count : histogram)
            total += double(count);
    }
    if (total == 0.0) throw std::invalid_argument("the volume's histogram holds no voxel");
    const double binWidth = (valueMax - valueMin) / double(histogram.size());
    const double target = percent / 100.0 * total;
    double below = 0.0;
    for (std::size_t i = first; i < histogram.size(); ++i) {
        const double count = double(histogram[i]);
        if (count == 0.0) continue;
        if (below + count >= target)
            return std::min(valueMax, valueMin + (double(i) + (target - below) / count) * binWidth);
        below += count;
    }
    return valueMax;
}

// ---- TransferFunctionTable --------------------------------------------------------------

TransferFunctionTable::TransferFunctionTable(double domainMinIn, double domainMaxIn,
                                             std::vector<float> rgbaIn)
    : domainMin(domainMinIn), domainMax(domainMaxIn), rgba(std::move(rgbaIn)) {
    if (!std::isfinite(domainMin) || !std::isfinite(domainMax) || !(domainMax > domainMin))
        throw std::invalid_argument(
            "TransferFunctionTable: domain is not a finite, non-empty interval");
    if (rgba.size() % 4 != 0 || rgba.size() / 4 < 2 ||
        rgba.size() / 4 > TransferFunction::kMaxTableEntries)
        throw std::invalid_argument(
            "TransferFunctionTable: rgba must hold 4 floats for each of 2 to " +
            std::to_string(TransferFunction::kMaxTableEntries) + " entries");
    entries = std::uint32_t(rgba.size() / 4);
    // Sparse table for range maxima: level k holds the max alpha of [i, i + 2^k).
    const auto levels = std::size_t(std::bit_width(entries));
    mAlphaMax.assign(levels * entries, 0.0f);
    for (std::uint32_t i = 0; i < entries; ++i)
        mAlphaMax[i] = rgba[4 * std::size_t(i) + 3];
    for (std::size_t k = 1; k < levels; ++k) {
        const float* prev = &mAlphaMax[(k - 1) * entries];
        float* cur = &mAlphaMax[k * entries];
        const std::size_t half = std::size_t(1) << (k - 1);
        for (std::size_t i = 0; i + 2 * half <= entries; ++i)
            cur[i] = std::max(prev[i], prev[i + half]);
    }
}

namespace {

/// Table position of `value`: (value - domainMin) / span * (entries - 1), clamped; NaN -> 0.
double tablePosition(const TransferFunctionTable& t, double value) {
    const double last = double(t.entries - 1);
    const double u = (value - t.domainMin) / (t.domainMax - t.domainMin) * last;
    if (!(u > 0.0)) return 0.0;
    return std::min(u, last);
}

} // namespace

std::array<float, 4> TransferFunctionTable::lookup(double value) const {
    const double u = tablePosition(*this, value);
    const auto k = std::min(std::uint32_t(u), entries - 2);
    const double t = u - double(k);
    const float* a = &rgba[4 * std::size_t(k)];
    std::array<float, 4> out{};
    for (std::size_t c = 0; c < 4; ++c)
        out[c] = float(double(a[c]) * (1.0 - t) + double(a[c + 4]) * t);
    return out;
}

double TransferFunctionTable::maxOpacity(double lo, double hi) const {
    std::uint32_t i = 0, j = entries - 1;
    if (!std::isnan(lo) && !std::isnan(hi)) {
        if (lo > hi) std::swap(lo, hi);
        i = std::uint32_t(std::floor(tablePosition(*this, lo)));
        j = std::uint32_t(std::ceil(tablePosition(*this, hi)));
    }
    const std::size_t k = std::size_t(std::bit_width(j - i + 1)) - 1;
    const float* level = &mAlphaMax[k * entries];
    return double(std::max(level[i], level[j + 1 - (std::size_t(1) << k)]));
}

// ---- TransferFunction -------------------------------------------------------------------

TransferFunction TransferFunction::parse(const std::string& jsonText, const std::string& sourceName,
                                         const VolumeValueStats& stats) {
    checkStats(stats);
    const Json doc = parseJson(jsonText, sourceName);
    if (!doc.is_object())
        fail(sourceName, "(document)", std::string("expected an object, got ") + doc.type_name());
    checkTopLevelKeys(doc, sourceName);
    std::string name = doc.contains("name") ? doc["name"].get<std::string>()
                                            : std::filesystem::path(sourceName).stem().string();
    std::optional<bool> shading;
    if (doc.contains("shading")) shading = doc["shading"].get<bool>();
    TransferFunction tf =
        fromPoints(parsePoints(doc, sourceName), sourceName, stats, std::move(name), shading);
    if (doc.contains("description")) tf.mDescription = doc["description"].get<std::string>();
    return tf;
}

TransferFunction TransferFunction::fromPoints(const std::vector<PointSpec>& points,
                                              const std::string& sourceName,
                                              const VolumeValueStats& stats, std::string name,
                                              std::optional<bool> shading) {
    checkStats(stats);
    if (points.empty()) fail(sourceName, "points", "empty: give at least one point");
    if (points.size() > kMaxPoints)
        fail(sourceName, "points",
             std::to_string(points.size()) + " points, more than " + std::to_string(kMaxPoints));
    std::vector<ControlPoint> placed;
    placed.reserve(points.size());
    for (std::size_t i = 0; i < points.size(); ++i)
        placed.push_back(place(points[i], stats, sourceName, "points[" + std::to_string(i) + "]"));
    TransferFunction tf;
    tf.mName = std::move(name);
    tf.mShading = shading;
    tf.setPoints(std::move(placed), stats);
    return tf;
}

void TransferFunction::setPoints(std::vector<ControlPoint> points, const VolumeValueStats& stats) {
    std::stable_sort(
        points.begin(), points.end(),
        [](const ControlPoint& a, const ControlPoint& b) { return a.value < b.value; });
    mPoints = std::move(points);
    mDomainMin = stats.valueMin;
    mDomainMax = stats.valueMax > stats.valueMin ? stats.valueMax : stats.valueMin + 1.0;
    std::uint64_t h = 0xcbf29ce484222325ull;
    h = fnv1a(h, &mDomainMin, sizeof mDomainMin);
    h = fnv1a(h, &mDomainMax, sizeof mDomainMax);
    for (const ControlPoint& p : mPoints) {
        h = fnv1a(h, &p.value, sizeof p.value);
        h = fnv1a(h, p.rgba.data(), sizeof p.rgba);
    }
    mContentHash = h;
}

bool TransferFunction::sameFunction(const TransferFunction& other) const {
    if (mContentHash != other.mContentHash || mDomainMin != other.mDomainMin ||
        mDomainMax != other.mDomainMax || mPoints.size() != other.mPoints.size())
        return false;
    for (std::size_t i = 0; i < mPoints.size(); ++i)
        if (mPoints[i].value != other.mPoints[i].value || mPoints[i].rgba != other.mPoints[i].rgba)
            return false;
    return true;
}

bool TransferFunction::isPreset(const std::string& name) {
    for (std::size_t i = 0; i < detail::kTfPresetCount; ++i)
        if (name == detail::kTfPresets[i].name) return true;
    return false;
}

TransferFunction TransferFunction::preset(const std::string& name, const VolumeValueStats& stats) {
    for (std::size_t i = 0; i < detail::kTfPresetCount; ++i)
        if (name == detail::kTfPresets[i].name)
            return parse(detail::kTfPresets[i].json, "<preset " + name + ">", stats);
    fail("presets", "name", "no such preset; presets: " + presetList());
}

std::vector<std::string> TransferFunction::presetNames() {
    std::vector<std::string> names;
    for (std::size_t i = 0; i < detail::kTfPresetCount; ++i)
        names.emplace_back(detail::kTfPresets[i].name);
    std::sort(names.begin(), names.end());
    return names;
}

std::array<float, 4> TransferFunction::evaluate(double value) const {
    const auto after =
        std::upper_bound(mPoints.begin(), mPoints.end(), value,
                         [](double v, const ControlPoint& p) { return v < p.value; });
    if (after == mPoints.begin()) return mPoints.front().rgba;
    if (after == mPoints.end()) return mPoints.back().rgba;
    const ControlPoint& a = *(after - 1);
    const ControlPoint& b = *after;
    const double t = (value - a.value) / (b.value - a.value);
    std::array<float, 4> out{};
    for (std::size_t c = 0; c < 4; ++c)
        out[c] = float(double(a.rgba[c]) * (1.0 - t) + double(b.rgba[c]) * t);
    return out;
}

TransferFunctionTable TransferFunction::table(double stepVoxels, std::uint32_t entries) const {
    if (!(std::isfinite(stepVoxels) && stepVoxels > 0.0))
        throw std::invalid_argument("TransferFunction::table: stepVoxels " +
                                    formatNumber(stepVoxels) + " is not finite and > 0");
    if (entries < 2 || entries > kMaxTableEntries)
        throw std::invalid_argument("TransferFunction::table: entries " + std::to_string(entries) +
                                    " outside [2, " + std::to_string(kMaxTableEntries) + "]");
    std::vector<float> rgba(std::size_t(entries) * 4);
    const double span = mDomainMax - mDomainMin, last = double(entries - 1);
    for (std::uint32_t i = 0; i < entries; ++i) {
        const double value = i + 1 == entries ? mDomainMax : mDomainMin + span * (double(i) / last);
        const auto c = evaluate(value);
        std::copy(c.begin(), c.end(), rgba.begin() + 4 * std::ptrdiff_t(i));
    }
    snapPeaks(rgba, entries);
    for (std::size_t i = 3; i < rgba.size(); i += 4)
        rgba[i] = correctOpacity(rgba[i], stepVoxels);
    return TransferFunctionTable(mDomainMin, mDomainMax, std::move(rgba));
}

PreintegratedTable TransferFunction::preintegrated(std::uint32_t entries) const {
    const TransferFunctionTable plain = table(1.0, entries);
    PreintegratedTable pre;
    pre.domainMin = mDomainMin;
    pre.domainMax = mDomainMax;
    pre.entries = entries;
    pre.table.resize(entries);
    for (std::uint32_t i = 0; i < entries; ++i) {
        const float* c = &plain.rgba[4 * std::size_t(i)];
        const double alpha = double(c[3]);
        const double tau = alpha >= 1.0
                               ? PreintegratedTable::kMaxExtinction
                               : std::min(-std::log1p(-alpha), PreintegratedTable::kMaxExtinction);
        auto& e = pre.table[i];
        e.rate[0] = float(tau);
        for (int k = 0; k < 3; ++k)
            e.rate[k + 1] = float(double(e.rate[0]) * double(c[k]));
    }
    // Trapezoids are exact for functions linear between entries; zero rates add exactly 0.
    for (int k = 0; k < 4; ++k)
        pre.table[0].integral[k] = 0.0;
    for (std::uint32_t i = 1; i < entries; ++i)
        for (int k = 0; k < 4; ++k)
            pre.table[i].integral[k] =
                pre.table[i - 1].integral[k] +
                0.5 * (double(pre.table[i - 1].rate[k]) + double(pre.table[i].rate[k]));
    return pre;
}

void TransferFunction::snapPeaks(std::vector<float>& rgba, std::uint32_t entries) const {
    // A point more opaque than both entries around it is a peak the linear table would
    // flatten (or, narrower than a cell, lose): the nearer entry takes its RGBA.
    const double last = double(entries - 1);
    for (const ControlPoint& p : mPoints) {
        const double u = (p.value - mDomainMin) / (mDomainMax - mDomainMin) * last;
        if (!(u > 0.0 && u < last)) continue; // at or beyond the ends, whose entries are exact
        const auto k = std::min(std::uint32_t(u), entries - 2);
        const std::size_t lo = 4 * std::size_t(k);
        if (p.rgba[3] <= std::max(rgba[lo + 3], rgba[lo + 7])) continue;
        const std::size_t nearest = u - double(k) < 0.5 ? lo : lo + 4;
        std::copy(p.rgba.begin(), p.rgba.end(), rgba.begin() + std::ptrdiff_t(nearest));
    }
}

float TransferFunction::correctOpacity(float alpha, double stepVoxels) {
    if (!(alpha > 0.0f)) return 0.0f;
    if (alpha >= 1.0f) return 1.0f;
    const double corrected = -std::expm1(stepVoxels * std::log1p(-double(alpha)));
    // A tiny opacity must stay non-zero: empty-space skipping relies on alpha > 0 there.
    return std::max(float(corrected), std::numeric_limits<float>::min());
}

} // namespace bc::render

// The catalog of a brickcastd.toml: [[volume]] entries (a store or a generated volume) and the
// [[preset]] transfer functions a config adds to the built-in ones.
#include "server/detail/DaemonConfigReader.h"

#include "brickstore/Readers.h"
#include "protocol/Wire.h"
#include "render/Error.h"
#include "render/TransferFunction.h"
#include "server/detail/DaemonConfigChecks.h"

#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>

namespace bc::server::detail {
namespace {

/// Most [[preset]] entries a config may add.
constexpr std::size_t kMaxPresets = 256;

/// Preset files are a few kilobytes; the config refuses anything far larger.
constexpr std::uintmax_t kMaxPresetFileBytes = 1u << 20;

} // namespace

std::array<std::uint64_t, 3> ConfigReader::readDims(const toml::table& t,
                                                    const std::string& prefix) const {
    const toml::node* node = t.get("dims");
    if (!node) fail(t.source(), prefix + "dims", "a generated volume needs dims = [X, Y, Z]");
    const toml::array* a = node->as_array();
    if (!a || a->size() != 3)
        fail(node->source(), prefix + "dims",
             "expected an array of 3 integers, e.g. [128, 128, 128]");
    std::array<std::uint64_t, 3> dims{};
    for (std::size_t i = 0; i < 3; ++i) {
        const auto* v = (*a)[i].as_integer();
        if (!v || v->get() < 8 || v->get() > 1024)
            fail((*a)[i].source(), prefix + "dims",
                 "element " + std::to_string(i + 1) + " must be an integer 8..1024");
        dims[i] = std::uint64_t(v->get());
    }
    return dims;
}

/// store, or generate with its dims: exactly one of the two.
void ConfigReader::readVolumeSource(const toml::table& t, const std::string& prefix,
                                    CatalogEntry& e) const {
    auto store = string(t, prefix, "store");
    auto generate = string(t, prefix, "generate");
    if (store && generate)
        fail(t.get("generate")->source(), prefix + "generate",
             "and store are both given: a volume is either a store or generated");
    if (!store && !generate)
        fail(t.source(), prefix + "store",
             "missing: give store (a .bcs path) or generate (a synthetic kind)");
    if (store) {
        if (store->empty()) fail(t.get("store")->source(), prefix + "store", "the path is empty");
        if (t.contains("dims"))
            fail(t.get("dims")->source(), prefix + "dims",
                 "only for generate: a store has its own");
        e.store = resolve(*store);
        return;
    }
    if (!brickstore::parseSynthKind(*generate))
        fail(t.get("generate")->source(), prefix + "generate",
             "'" + *generate + "' is not one of phantom, vessels, checker");
    e.generate = *generate;
    e.dims = readDims(t, prefix);
}

CatalogEntry ConfigReader::readVolume(const toml::table& t, const std::string& prefix) const {
    checkKeys(t, prefix, {"name", "store", "generate", "dims", "description", "optional"});
    CatalogEntry e;
    auto name = string(t, prefix, "name");
    if (!name) fail(t.source(), prefix + "name", "missing: every volume needs a name");
    if (auto why = volumeNameProblem(*name)) fail(t.get("name")->source(), prefix + "name", *why);
    e.name = *name;
    readVolumeSource(t, prefix, e);
    e.description = string(t, prefix, "description").value_or("");
    if (auto optional = boolean(t, prefix, "optional")) {
        if (!t.contains("store"))
            fail(t.get("optional")->source(), prefix + "optional",
                 "only for store: a generated volume is made when missing");
        e.optional = *optional;
    }
    return e;
}

void ConfigReader::readVolumes(const toml::table& root, DaemonConfig& c) const {
    const toml::node* node = root.get("volume");
    if (!node) fail(root.source(), "[[volume]]", "no volumes: the catalog needs at least one");
    const toml::array* list = node->as_array();
    if (!list || !list->is_array_of_tables())
        fail(node->source(), "volume", "expected [[volume]] tables");
    if (list->size() > protocol::kMaxVolumes)
        fail(node->source(), "[[volume]]",
             "more than " + std::to_string(protocol::kMaxVolumes) + " volumes");
    std::map<std::string, std::size_t> seen;
    for (std::size_t i = 0; i < list->size(); ++i) {
        const toml::table& t = *(*list)[i].as_table();
        const std::string prefix = "[[volume]] " + std::to_string(i + 1) + " .";
        CatalogEntry e = readVolume(t, prefix);
        if (auto [it, fresh] = seen.emplace(e.name, i + 1); !fresh)
            fail(t.get("name")->source(), prefix + "name",
                 "'" + e.name + "' is already [[volume]] " + std::to_string(it->second));
        c.volumes.push_back(std::move(e));
    }
}

/// The text of preset `file` (resolved), checked to be a transfer function.
std::string ConfigReader::readPresetFile(const toml::source_region& at, const std::string& prefix,
                                         const std::string& file) const {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec))
        fail(at, prefix + "file", "'" + file + "' is not a readable file");
    const auto bytes = std::filesystem::file_size(file, ec);
    if (ec || bytes > kMaxPresetFileBytes)
        fail(at, prefix + "file",
             "'" + file + "' " +
                 (ec ? ec.message() : "is over " + std::to_string(kMaxPresetFileBytes) + " bytes"));
    std::ifstream in(file, std::ios::binary);
    std::ostringstream text;
    text << in.rdbuf();
    if (!in) fail(at, prefix + "file", "'" + file + "' cannot be read");
    try { // placed for a stand-in volume: every placement works, so only the text can fail
        render::TransferFunction::parse(text.str(), file,
                                        render::VolumeValueStats{0.0, 1.0, {1, 1}});
    } catch (const render::RenderInputError& err) {
        fail(at, prefix + "file", err.what());
    }
    return text.str();
}

PresetEntry ConfigReader::readPreset(const toml::table& t, const std::string& prefix) const {
    checkKeys(t, prefix, {"name", "file"});
    PresetEntry e;
    auto name = string(t, prefix, "name");
    if (!name) fail(t.source(), prefix + "name", "missing: every preset needs a name");
    if (auto why = volumeNameProblem(*name)) fail(t.get("name")->source(), prefix + "name", *why);
    if (render::TransferFunction::isPreset(*name))
        fail(t.get("name")->source(), prefix + "name",
             "'" + *name + "' is a built-in preset; give yours another name");
    e.name = *name;
    auto file = string(t, prefix, "file");
    if (!file || file->empty())
        fail(file ? t.get("file")->source() : t.source(), prefix + "file",
             "missing: a transfer-function JSON file (configs/tf/README.md)");
    e.file = resolve(*file);
    e.json = readPresetFile(t.get("file")->source(), prefix, e.file);
    return e;
}

void ConfigReader::readPresets(const toml::table& root, DaemonConfig& c) const {
    const toml::node* node = root.get("preset");
    if (!node) return;
    const toml::array* list = node->as_array();
    if (!list || !list->is_array_of_tables())
        fail(node->source(), "preset", "expected [[preset]] tables");
    if (list->size() > kMaxPresets)
        fail(node->source(), "[[preset]]", "more than " + std::to_string(kMaxPresets) + " presets");
    std::map<std::string, std::size_t> seen;
    for (std::size_t i = 0; i < list->size(); ++i) {
        const toml::table& t = *(*list)[i].as_table();
        const std::string prefix = "[[preset]] " + std::to_string(i + 1) + " .";
        PresetEntry e = readPreset(t, prefix);
        if (auto [it, fresh] = seen.emplace(e.name, i + 1); !fresh)
            fail(t.get("name")->source(), prefix + "name",
                 "'" + e.name + "' is already [[preset]] " + std::to_string(it->second));
        c.presets.push_back(std::move(e));
    }
}

} // namespace bc::server::detail

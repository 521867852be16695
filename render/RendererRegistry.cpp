#include "render/RendererRegistry.h"

#include "render/CpuRaycaster.h"
#include "render/GpuRaycaster.h"
#include "render/GpuSplatter.h"
#include "render/HybridSplatter.h"
#include "render/ReferenceRenderer.h"

#include <stdexcept>

namespace bc::render {

const RendererRegistry& RendererRegistry::builtin() {
    static const RendererRegistry registry = [] {
        RendererRegistry r;
        r.add({.name = "gpu",
               .description = "GPU raycaster (OpenGL 4.5)",
               .needsGl = true,
               .regions = true,
               .parts = true,
               .create = [] { return std::make_unique<GpuRaycaster>(); }});
        r.add({.name = "cpu",
               .description = "CPU raycaster",
               .regions = true,
               .parts = true,
               .strided = true,
               .create = [] { return std::make_unique<CpuRaycaster>(); }});
        r.add({.name = "reference",
               .description = "CPU reference raycaster (double precision, no skipping)",
               .sharedPerVolume = true,
               .regions = true,
               .create = [] { return std::make_unique<ReferenceRenderer>(); }});
        r.add({.name = "splat",
               .description = "hybrid forward splatter (CPU)",
               .regions = true,
               .objectOrder = true,
               .create = [] { return std::make_unique<HybridSplatter>(); }});
        r.add({.name = "splat-gpu",
               .description = "hybrid forward splatter (OpenGL 4.5)",
               .needsGl = true,
               .regions = true,
               .objectOrder = true,
               .create = [] { return std::make_unique<GpuSplatter>(); }});
        return r;
    }();
    return registry;
}

void RendererRegistry::add(RendererKind kind) {
    if (find(kind.name)) throw std::invalid_argument("renderer '" + kind.name + "' is registered");
    mKinds.push_back(std::move(kind));
}

const RendererKind* RendererRegistry::find(std::string_view name) const {
    for (const auto& k : mKinds)
        if (k.name == name) return &k;
    return nullptr;
}

std::unique_ptr<Renderer> RendererRegistry::create(std::string_view name) const {
    const RendererKind* kind = find(name);
    if (!kind) {
        std::string list;
        for (const auto& k : mKinds)
            list += (list.empty() ? "" : ", ") + k.name;
        throw std::invalid_argument(
            "no renderer named '" + std::string(name) + "' (renderers: " + list +
            (name == "auto" ? "; auto is resolved to one of them by resolveRenderer)" : ")"));
    }
    return kind->create();
}

std::vector<std::string> RendererRegistry::names() const {
    std::vector<std::string> out;
    for (const auto& k : mKinds)
        out.push_back(k.name);
    return out;
}

} // namespace bc::render

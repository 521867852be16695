// One list of renderer names: every renderer the protocol can ask for is a kind of the renderer
// registry under the name the programs and the metrics use, and every kind can be asked for.
#include "protocol/Wire.h"
#include "render/RendererRegistry.h"

#include <gtest/gtest.h>

#include <string>

namespace bc::server {
namespace {

TEST(RendererNames, TheProtocolsRenderersAreTheRegistrysKindsByTheSameNames) {
    const auto& registry = render::RendererRegistry::builtin();
    for (std::uint8_t v = 0; v <= std::uint8_t(protocol::Renderer::Auto); ++v) {
        const auto renderer = protocol::Renderer(v);
        const std::string name(protocol::rendererName(renderer));
        EXPECT_EQ(protocol::rendererNamed(name), renderer) << name;
        if (renderer == protocol::Renderer::Auto) {
            EXPECT_EQ(registry.find(name), nullptr) << "auto is a choice, not a kind";
            continue;
        }
        EXPECT_NE(registry.find(name), nullptr) << name << " is not a kind of the registry";
    }
    for (const std::string& name : registry.names())
        EXPECT_TRUE(protocol::rendererNamed(name).has_value())
            << "the protocol cannot ask for the registry's " << name;
    EXPECT_EQ(protocol::rendererName(protocol::Renderer(200)), "unknown");
    EXPECT_FALSE(protocol::rendererNamed("GPU").has_value());
}

} // namespace
} // namespace bc::server

// The decoder and the renderers judge a camera the same way: a SetCamera the decoder passes is
// one every renderer draws (a finite view basis), and one it refuses is one Camera::validate
// refuses. The two live in modules that cannot see each other (protocol/MessageRules.cpp and
// render/Camera.cpp); this test holds them to one rule, down to the extremes of a double.
#include "protocol/Messages.h"
#include "protocol/detail/MessageRules.h"
#include "render/Camera.h"
#include "server/ViewRequest.h"

#include <glm/geometric.hpp>
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>
#include <stdexcept>
#include <string>
#include <vector>

namespace bc::server {
namespace {

bool decoderPasses(const protocol::SetCamera& c) {
    return !protocol::detail::firstViolation(protocol::Message{c}).has_value();
}

bool rendererPasses(const protocol::SetCamera& c) {
    try {
        toCamera(c).validate();
        return true;
    } catch (const std::invalid_argument&) {
        return false;
    }
}

bool finiteBasis(const protocol::SetCamera& c) {
    const render::ViewBasis b = render::ViewBasis::fromValid(toCamera(c), 64, 48);
    for (const glm::dvec3& v : {b.forward, b.right, b.upScaled})
        if (!std::isfinite(v.x) || !std::isfinite(v.y) || !std::isfinite(v.z) ||
            glm::length(v) == 0.0)
            return false;
    return true;
}

std::string show(const protocol::SetCamera& c) {
    char s[256];
    std::snprintf(s, sizeof s, "eye (%g, %g, %g) target (%g, %g, %g) up (%g, %g, %g)", c.eye[0],
                  c.eye[1], c.eye[2], c.target[0], c.target[1], c.target[2], c.up[0], c.up[1],
                  c.up[2]);
    return s;
}

protocol::SetCamera camera(std::array<double, 3> eye, std::array<double, 3> target,
                           std::array<double, 3> up) {
    protocol::SetCamera c;
    c.eye = eye;
    c.target = target;
    c.up = up;
    return c;
}

void expectAgreement(const protocol::SetCamera& c) {
    const bool decoder = decoderPasses(c), renderer = rendererPasses(c);
    EXPECT_EQ(decoder, renderer) << show(c) << ": the decoder " << (decoder ? "passes" : "refuses")
                                 << " it, the renderer " << (renderer ? "draws" : "refuses")
                                 << " it";
    if (decoder && renderer) {
        EXPECT_TRUE(finiteBasis(c)) << show(c) << ": no finite view basis";
    }
}

TEST(CameraRules, TheDecoderAndTheRendererAgreeOnCamerasAtTheExtremesOfADouble) {
    const double big = 1e300, huge = std::numeric_limits<double>::max() / 4, tiny = 1e-300,
                 denormal = std::numeric_limits<double>::denorm_min() * 8;
    const std::vector<protocol::SetCamera> cameras = {
        camera({0, 0, 0}, {1, 0, 0}, {0, 0, 1}),
        camera({0, 0, 0}, {big, big, 0}, {0, 0, 1}),
        camera({0, 0, 0}, {huge, huge, huge}, {0, 0, 1}),
        camera({-huge, 0, 0}, {huge, 0, 0}, {0, 0, 1}),
        camera({0, 0, 0}, {tiny, tiny, 0}, {0, 0, 1}),
        camera({0, 0, 0}, {denormal, 0, 0}, {0, 0, 1}),
        camera({1, 2, 3}, {1 + 4.4e-16, 2, 3}, {0, 0, 1}),
        camera({0, 0, 0}, {1, 0, 0}, {0, 0, big}),
        camera({0, 0, 0}, {1, 0, 0}, {0, 0, tiny}),
        camera({0, 0, 0}, {1, 0, 0}, {0, 0, 1e-9}),
        camera({0, 0, 0}, {1, 0, 0}, {1, 0, 1e-9}),
        camera({0, 0, 0}, {1, 0, 0}, {1, 0, 0}),
        camera({0, 0, 0}, {0, 0, 0}, {0, 0, 1}),
        camera({5, 5, 5}, {5, 5, 5}, {0, 1, 0}),
    };
    for (const auto& c : cameras)
        expectAgreement(c);
}

TEST(CameraRules, TheDecoderAndTheRendererAgreeOnRandomCamerasOfEveryMagnitude) {
    std::mt19937_64 rng(20261207);
    std::uniform_int_distribution<int> exponent(-320, 307);
    std::uniform_real_distribution<double> mantissa(-1.0, 1.0);
    std::bernoulli_distribution zero(0.1), nearlyParallel(0.2);
    auto value = [&] { return zero(rng) ? 0.0 : mantissa(rng) * std::pow(10.0, exponent(rng)); };
    for (int i = 0; i < 20000; ++i) {
        protocol::SetCamera c = camera({value(), value(), value()}, {value(), value(), value()},
                                       {value(), value(), value()});
        if (nearlyParallel(rng)) // up along the view, give or take a little
            for (int a = 0; a < 3; ++a)
                c.up[a] = (c.target[a] - c.eye[a]) * (1.0 + 1e-12 * mantissa(rng));
        expectAgreement(c);
        if (HasFailure()) break; // the first disagreement says enough
    }
}

} // namespace
} // namespace bc::server

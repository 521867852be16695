// The shaders of render/shaders: every program the renderers build compiles and links with the
// driver's compiler, a broken line is reported with its file and line (through the #defines
// and #include expansion), and every embedded file belongs to a program.
#include "RenderTestSupport.h"

#include "render/Error.h"
#include "render/detail/ShaderPrograms.h"
#include "render/detail/ShaderSources.h"

#include <set>
#include <sstream>

namespace bc::render {
namespace {

using detail::ShaderProgram;
using detail::ShaderProgramSource;

/// "splat: splat_quad.vert.glsl, splat.frag.glsl (splat.frag.glsl: line 1000 + k is line k of
/// footprint.inc.glsl)".
std::string describe(const ShaderProgramSource& p) {
    std::string files, snippets;
    for (const gl::ShaderStage& stage : p.stages) {
        files += (files.empty() ? "" : ", ") + stage.file;
        std::istringstream includes(detail::findShaderFile(stage.file)->includes);
        int n = 0;
        for (std::string snippet; includes >> snippet;)
            snippets += " (" + stage.file + ": line " + std::to_string(1000 * ++n) +
                        " + k is line k of " + snippet + ")";
    }
    return p.name + ": " + files + snippets;
}

/// 1-based number of the line of render/shaders/`file` (the file in the source tree) that
/// reads `text`, or 0.
int lineInSourceFile(const std::string& file, const std::string& text) {
    std::ifstream in(std::string(BC_CONFIGS_DIR) + "/../render/shaders/" + file);
    int number = 0;
    for (std::string line; std::getline(in, line);) {
        ++number;
        if (line == text) return number;
    }
    return 0;
}

/// Whether a compiler log points at `line`, in the forms of Mesa ("0:12(5): error"), NVIDIA
/// ("0(12) : error") and AMD ("ERROR: 0:12: ").
bool logPointsAt(const std::string& log, int line) {
    const std::string l = std::to_string(line);
    for (const std::string& form : {":" + l + "(", "(" + l + ")", ":" + l + ":"})
        if (log.find(form) != std::string::npos) return true;
    return false;
}

/// Two kinds of error, which compilers locate apart: the parser's and the type checker's.
const char* const kBrokenLines[] = {"    float = ;", "    bcNoSuchFunction();"};

/// The message of compiling `program` with `marker` (a whole line of one of its stages)
/// replaced by `broken`.
std::string errorWithBrokenLine(ShaderProgram program, const std::string& marker,
                                const std::string& broken) {
    ShaderProgramSource p = detail::shaderProgramSource(program);
    bool replaced = false;
    for (gl::ShaderStage& stage : p.stages) {
        const std::size_t at = stage.source.find("\n" + marker + "\n");
        if (at == std::string::npos) continue;
        stage.source.replace(at + 1, marker.size(), broken);
        replaced = true;
    }
    EXPECT_TRUE(replaced) << "no line '" << marker << "' in " << describe(p);
    try {
        gl::buildProgram(p.name, p.stages);
    } catch (const RenderError& e) {
        return e.what();
    }
    return "";
}

TEST(ShaderCompile, EveryProgramCompilesAndLinksWithTheDriversCompiler) {
    test::glContext();
    for (ShaderProgram program : detail::allShaderPrograms()) {
        const ShaderProgramSource source = detail::shaderProgramSource(program);
        try {
            detail::buildShaderProgram(program); // as the renderers build it
        } catch (const RenderError& e) {
            ADD_FAILURE() << describe(source) << "\n" << e.what();
        }
    }
}

// An error in splat.frag.glsl (which gets a #define and includes footprint.inc.glsl) is
// reported on its line of the file, and one in the snippet on 1000 + its line of the snippet.
TEST(ShaderCompile, ABrokenLineIsReportedWithItsFileAndLine) {
    test::glContext();
    const std::string own = "    d *= uInvRadius;";
    const int ownLine = lineInSourceFile("splat.frag.glsl", own);
    ASSERT_GT(ownLine, 0) << "no line '" << own << "' in render/shaders/splat.frag.glsl";
    const std::string snippet = "    int i = min(int(u), kTexels - 2);";
    const int snippetLine = lineInSourceFile("footprint.inc.glsl", snippet);
    ASSERT_GT(snippetLine, 0) << "no line '" << snippet << "' in footprint.inc.glsl";
    for (const std::string broken : kBrokenLines) {
        const std::string ownError = errorWithBrokenLine(ShaderProgram::Splat, own, broken);
        EXPECT_NE(ownError.find("splat.frag.glsl"), std::string::npos) << ownError;
        EXPECT_TRUE(logPointsAt(ownError, ownLine)) << "line " << ownLine << ":\n" << ownError;
        const std::string snippetError =
            errorWithBrokenLine(ShaderProgram::SplatPoint, snippet, broken);
        EXPECT_NE(snippetError.find("splat_point.frag.glsl"), std::string::npos) << snippetError;
        EXPECT_TRUE(logPointsAt(snippetError, 1000 + snippetLine))
            << "line 1000 + " << snippetLine << ":\n"
            << snippetError;
    }
}

TEST(ShaderFiles, EveryEmbeddedFileBelongsToAProgram) {
    std::set<std::string> used, names;
    for (ShaderProgram program : detail::allShaderPrograms()) {
        const ShaderProgramSource p = detail::shaderProgramSource(program);
        EXPECT_TRUE(names.insert(p.name).second) << "two programs named " << p.name;
        for (const gl::ShaderStage& stage : p.stages) {
            used.insert(stage.file);
            std::istringstream includes(detail::findShaderFile(stage.file)->includes);
            for (std::string snippet; includes >> snippet;)
                used.insert(snippet);
        }
    }
    ASSERT_GT(detail::kShaderFileCount, 0u);
    for (std::size_t i = 0; i < detail::kShaderFileCount; ++i)
        EXPECT_TRUE(used.count(detail::kShaderFiles[i].name))
            << "render/shaders/" << detail::kShaderFiles[i].name
            << " is embedded but no program of render/detail/ShaderPrograms.cpp uses it";
}

TEST(ShaderFiles, AnUnknownFileIsNamed) {
    try {
        detail::shaderStage("nosuch.frag.glsl");
        FAIL() << "no throw";
    } catch (const RenderError& e) {
        EXPECT_NE(std::string(e.what()).find("nosuch.frag.glsl"), std::string::npos) << e.what();
    }
    EXPECT_THROW(detail::shaderStage("footprint.inc.glsl"), RenderError); // a snippet: no stage
}

} // namespace
} // namespace bc::render

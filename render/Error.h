#pragma once
// Errors of the render module. Start-up failures (no usable EGL, a shader that does not
// compile, a bad transfer-function file) throw; expected outcomes are return values.
#include <stdexcept>
#include <string>

namespace bc::render {

/// The GPU or its driver cannot do what was asked (no EGL display, no OpenGL 4.5 context,
/// shader compile or link failure, out of GPU memory).
class RenderError : public std::runtime_error {
  public:
    using std::runtime_error::runtime_error;
};

/// A transfer function, camera or image file is malformed: names the file and field at fault.
class RenderInputError : public std::runtime_error {
  public:
    RenderInputError(const std::string& file, const std::string& field, const std::string& why)
        : std::runtime_error(file + ": " + field + ": " + why), mFile(file), mField(field) {}
    const std::string& file() const { return mFile; }
    const std::string& field() const { return mField; }

  private:
    std::string mFile, mField;
};

} // namespace bc::render

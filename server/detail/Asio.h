#pragma once
// Asio as every brickcast target compiles it: the settings come from the bc_asio CMake target
// (CMakeLists.txt). Asio's inline aligned_new/aligned_delete depend on them; a file compiled
// without them would get Asio's own guess, which depends on whether a standard header came
// first, and the program would link two versions (allocation by one, release by the other).
#if !defined(ASIO_STANDALONE) || !defined(ASIO_NO_DEPRECATED) ||                                   \
    !defined(ASIO_DISABLE_STD_ALIGNED_ALLOC)
#error "Asio must be compiled with the bc_asio target's definitions: link bc_asio"
#endif
#include <asio.hpp>

#pragma once
// Boost.Asio as every brickcast target compiles it: the settings come from the bc_asio CMake
// target (CMakeLists.txt). Asio's inline aligned_new/aligned_delete depend on them; a file
// compiled without them would get Asio's own guess, which depends on whether a standard header
// came first, and the program would link two versions (allocation by one, release by the
// other). Boost.Asio rather than standalone Asio because Boost.Beast (the WebSocket and HTTP
// transport, server/detail/WebListener.h) runs on it: one Asio, one event loop.
#if !defined(BOOST_ASIO_NO_DEPRECATED) || !defined(BOOST_ASIO_DISABLE_STD_ALIGNED_ALLOC)
#error "Asio must be compiled with the bc_asio target's definitions: link bc_asio"
#endif
// Boost 1.74's awaitable.hpp uses std::exchange without including <utility> (fixed in 1.75).
#include <utility>

#include <boost/asio.hpp>

namespace asio = boost::asio;

namespace bc::server {
using IoError = boost::system::error_code; ///< what Asio reports
} // namespace bc::server

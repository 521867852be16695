#include "server/detail/Acceptor.h"

#include "server/Error.h"

namespace bc::server::detail {

void listenOn(asio::ip::tcp::acceptor& acceptor, const std::string& host, std::uint16_t port,
              const std::string& what) {
    try {
        asio::ip::tcp::resolver resolver(acceptor.get_executor());
        const auto ep =
            resolver.resolve(host, std::to_string(port), asio::ip::resolver_base::numeric_service)
                .begin()
                ->endpoint();
        acceptor.open(ep.protocol());
        acceptor.set_option(asio::socket_base::reuse_address(true));
        acceptor.bind(ep);
        acceptor.listen();
    } catch (const std::exception& e) {
        throw ConfigError(what + " " + host + ":" + std::to_string(port) + ": " + e.what());
    }
}

} // namespace bc::server::detail

#include "server/detail/Tls.h"

#include "server/DaemonConfig.h"
#include "server/Error.h"
#include "server/Log.h"

#include <boost/asio/ssl.hpp>

namespace bc::server::detail {

std::shared_ptr<TlsContext> makeTlsContext(const DaemonConfig& config) {
    if (config.tlsCert.empty()) return nullptr;
    auto tls = std::make_shared<TlsContext>(asio::ssl::context::tls_server);
    tls->set_options(asio::ssl::context::default_workarounds | asio::ssl::context::no_sslv2 |
                     asio::ssl::context::no_sslv3 | asio::ssl::context::no_tlsv1 |
                     asio::ssl::context::no_tlsv1_1 | asio::ssl::context::single_dh_use);
    auto load = [&](const std::string& key, const std::string& file, auto&& use) {
        IoError ec;
        use(file, ec);
        if (ec)
            throw ConfigError(config.source + ": server." + key + ": " + file + ": " +
                              ec.message());
    };
    load("tls_cert", config.tlsCert,
         [&](const std::string& f, IoError& ec) { tls->use_certificate_chain_file(f, ec); });
    load("tls_key", config.tlsKey, [&](const std::string& f, IoError& ec) {
        tls->use_private_key_file(f, asio::ssl::context::pem, ec);
    });
    if (SSL_CTX_check_private_key(tls->native_handle()) != 1)
        throw ConfigError(config.source + ": server.tls_key: " + config.tlsKey +
                          " is not the key of the certificate in " + config.tlsCert);
    return tls;
}

} // namespace bc::server::detail

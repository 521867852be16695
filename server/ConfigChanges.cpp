#include "server/ConfigChanges.h"

#include <functional>
#include <utility>

namespace bc::server {

std::vector<std::string> settingsAReloadKeeps(const DaemonConfig& running,
                                              const DaemonConfig& next) {
    using Same = std::function<bool(const DaemonConfig&, const DaemonConfig&)>;
    auto field = [](auto member) -> Same {
        return [member](const DaemonConfig& a, const DaemonConfig& b) {
            return a.*member == b.*member;
        };
    };
    const std::pair<const char*, Same> keys[] = {
        {"server.listen",
         [&](const DaemonConfig& a, const DaemonConfig& b) {
             return running.listenOverridden ||
                    (a.listenHost == b.listenHost && a.listenPort == b.listenPort);
         }},
        {"server.token", field(&DaemonConfig::token)},
        {"server.max_clients", field(&DaemonConfig::maxClients)},
        {"server.max_unauthenticated", field(&DaemonConfig::maxUnauthenticated)},
        {"server.store_dir", field(&DaemonConfig::storeDir)},
        {"server.metrics",
         [&](const DaemonConfig& a, const DaemonConfig& b) {
             return running.metricsOverridden ||
                    (a.metricsHost == b.metricsHost && a.metricsPort == b.metricsPort);
         }},
        {"server.web",
         [&](const DaemonConfig& a, const DaemonConfig& b) {
             return running.webOverridden || a.web == b.web;
         }},
        {"server.web_hosts", field(&DaemonConfig::webHosts)},
        {"server.tls_cert", field(&DaemonConfig::tlsCert)},
        {"server.tls_key", field(&DaemonConfig::tlsKey)},
        {"timeouts.handshake_ms", field(&DaemonConfig::handshakeTimeoutMs)},
        {"timeouts.read_ms", field(&DaemonConfig::readTimeoutMs)},
        {"timeouts.idle_ms", field(&DaemonConfig::idleTimeoutMs)},
        {"timeouts.write_ms", field(&DaemonConfig::writeTimeoutMs)},
        {"budgets.host_mb", field(&DaemonConfig::hostBudgetBytes)},
        {"budgets.gpu_mb", field(&DaemonConfig::gpuBudgetBytes)},
        {"frames.rest_ms", field(&DaemonConfig::restMs)},
        {"frames.write_queue", field(&DaemonConfig::writeQueueFrames)},
        {"frames.write_queue_mb", field(&DaemonConfig::writeQueueBytes)},
        {"frames.max_frame_gsamples", field(&DaemonConfig::maxFrameSamples)},
        {"frames.max_unsliced_gsamples", field(&DaemonConfig::maxUnslicedSamples)},
        {"frames.slice_ms", field(&DaemonConfig::sliceMs)},
        {"frames.interactive_ms", field(&DaemonConfig::interactiveMs)},
        {"frames.prefetch", field(&DaemonConfig::prefetch)},
        {"frames.cache_mb", field(&DaemonConfig::frameCacheBytes)},
        {"frames.cluster_timeout_ms", field(&DaemonConfig::clusterTimeoutMs)},
    };
    std::vector<std::string> changed;
    for (const auto& [key, same] : keys)
        if (!same(running, next)) changed.emplace_back(key);
    return changed;
}

} // namespace bc::server

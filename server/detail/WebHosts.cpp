#include "server/detail/WebHosts.h"

#include "server/DaemonConfig.h"

#include <algorithm>
#include <cctype>

namespace bc::server::detail {
namespace {

std::string lower(std::string_view text) {
    std::string s(text);
    std::transform(s.begin(), s.end(), s.begin(),
                   [](unsigned char c) { return char(std::tolower(c)); });
    return s;
}

/// "NAME" of "NAME", "NAME:PORT", "[V6]" or "[V6]:PORT" (brackets kept); nothing when the
/// value is malformed (an empty name, a port that is not 1..5 digits).
std::optional<std::string_view> nameOf(std::string_view host) {
    std::size_t end = host.size();
    if (!host.empty() && host.front() == '[') {
        end = host.find(']');
        if (end == std::string_view::npos) return std::nullopt;
        ++end;
    } else if (const auto colon = host.rfind(':'); colon != std::string_view::npos) {
        end = colon;
    }
    if (end == 0) return std::nullopt;
    if (end < host.size()) {
        const auto port = host.substr(end);
        if (port.size() < 2 || port.size() > 6 || port.front() != ':' ||
            !std::all_of(port.begin() + 1, port.end(),
                         [](unsigned char c) { return std::isdigit(c); }))
            return std::nullopt;
    }
    return host.substr(0, end);
}

/// The IP address a name spells ("10.0.0.5", "[::1]"), if it is one.
std::optional<asio::ip::address> addressIn(std::string_view name) {
    std::string text(name);
    if (text.size() > 2 && text.front() == '[' && text.back() == ']')
        text = text.substr(1, text.size() - 2);
    IoError ec;
    const auto a = asio::ip::make_address(text, ec);
    if (ec) return std::nullopt;
    return a;
}

/// An IP address as a Host header spells it: IPv6 in brackets.
std::string spelled(std::string address) {
    if (address.find(':') == std::string::npos) return address;
    address.insert(address.begin(), '[');
    address.push_back(']');
    return address;
}

} // namespace

WebHosts::WebHosts(const std::string& listenHost, const asio::ip::address& bound,
                   std::vector<std::string> extra)
    : mNames(std::move(extra)), mAnyAddress(bound.is_unspecified()) {
    mNames.push_back(spelled(bound.to_string()));
    mNames.push_back(lower(spelled(listenHost)));
    if (bound.is_loopback() || isLoopback(listenHost))
        for (const char* name : {"localhost", "127.0.0.1", "[::1]"})
            mNames.emplace_back(name);
}

std::optional<std::string> WebHosts::hostProblem(std::string_view host) const {
    const auto name = nameOf(host);
    if (!name) return "Host '" + std::string(host.substr(0, 200)) + "' is malformed";
    const std::string n = lower(*name);
    if (std::find(mNames.begin(), mNames.end(), n) != mNames.end()) return std::nullopt;
    if (mAnyAddress && addressIn(n)) return std::nullopt;
    return "Host '" + std::string(host.substr(0, 200)) +
           "' is not a name of this server (add it to server.web_hosts)";
}

std::optional<std::string> WebHosts::originProblem(std::string_view origin, std::string_view host) {
    const std::string o = lower(origin), h = lower(host);
    for (std::string_view scheme : {"http://", "https://"})
        if (o.size() == scheme.size() + h.size() && o.starts_with(scheme) && o.ends_with(h))
            return std::nullopt;
    return "Origin '" + std::string(origin.substr(0, 200)) + "' is not this server's (http://" +
           std::string(host.substr(0, 200)) + ")";
}

} // namespace bc::server::detail

#include "server/detail/AuthThrottle.h"

#include <algorithm>

namespace bc::server::detail {

std::chrono::milliseconds AuthThrottle::waitAfter(unsigned failures) {
    if (failures == 0) return std::chrono::milliseconds(0);
    const unsigned doublings = std::min(failures - 1, 16u);
    return std::min(kFirstWait * (1u << doublings), kLongestWait);
}

std::optional<AuthThrottle::Clock::time_point> AuthThrottle::admit(const std::string& address,
                                                                   Clock::time_point now) {
    const auto it = mEntries.find(address);
    if (it == mEntries.end()) return now;
    Entry& e = it->second;
    if (now - e.last > kForgetAfter && !e.waiting) {
        mEntries.erase(it);
        return now;
    }
    const auto at = std::max(now, e.next);
    if (at > now) {
        if (e.waiting) return std::nullopt;
        e.waiting = true;
        ++mDelayed;
    }
    e.next = at + waitAfter(e.failures);
    return at;
}

std::chrono::milliseconds AuthThrottle::failed(const std::string& address, Clock::time_point now) {
    ++mFailures;
    if (!mEntries.contains(address)) makeRoom(now);
    Entry& e = mEntries[address];
    e.waiting = false;
    ++e.failures;
    e.last = now;
    const auto wait = waitAfter(e.failures);
    e.next = std::max(e.next, now + wait);
    return std::chrono::duration_cast<std::chrono::milliseconds>(e.next - now);
}

void AuthThrottle::succeeded(const std::string& address) {
    mEntries.erase(address);
}

void AuthThrottle::abandoned(const std::string& address) {
    if (const auto it = mEntries.find(address); it != mEntries.end()) it->second.waiting = false;
}

void AuthThrottle::makeRoom(Clock::time_point now) {
    if (mEntries.size() < kMaxAddresses) return;
    std::erase_if(mEntries, [&](const auto& e) { return now - e.second.last > kForgetAfter; });
    if (mEntries.size() < kMaxAddresses) return;
    const auto oldest = std::min_element(mEntries.begin(), mEntries.end(), [](auto& a, auto& b) {
        return a.second.last < b.second.last;
    });
    mEntries.erase(oldest);
}

} // namespace bc::server::detail

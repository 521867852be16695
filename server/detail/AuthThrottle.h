#pragma once
// Wrong tokens slow down per source address (private to server/): after a failure, that
// address's next Auth is checked only after a wait that doubles with each failure (100 ms,
// 200 ms, ... at most 2 s), whichever connection it comes on, and one Auth at a time waits
// (another is refused unchecked), so tokens from one address are checked at most ten a second
// and fewer as the failures go on. A correct token resets the address; a quiet minute forgets
// it. A correct token waits its turn as a wrong one does: an answer that came sooner for a
// correct token would tell a guesser when it was right. Network thread only.
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <unordered_map>

namespace bc::server::detail {

class AuthThrottle {
  public:
    using Clock = std::chrono::steady_clock;
    static constexpr auto kFirstWait = std::chrono::milliseconds(100);
    static constexpr auto kLongestWait = std::chrono::milliseconds(2000);
    static constexpr auto kForgetAfter = std::chrono::seconds(60);
    /// Addresses remembered at once; beyond it the least recently failed is forgotten.
    static constexpr std::size_t kMaxAddresses = 4096;

    /// When an Auth from `address` that arrived at `now` may be checked: `now`, or later while
    /// the address is paying for wrong tokens; nothing while another Auth of the address waits
    /// (refuse this one unchecked). The time is taken: a later Auth waits behind it.
    std::optional<Clock::time_point> admit(const std::string& address, Clock::time_point now);
    /// The token checked was wrong. Returns the wait before the address's next check.
    std::chrono::milliseconds failed(const std::string& address, Clock::time_point now);
    /// The token checked was right: the address starts afresh.
    void succeeded(const std::string& address);
    /// An Auth admitted to wait will not be checked (its connection ended first).
    void abandoned(const std::string& address);

    std::uint64_t failures() const { return mFailures; } ///< wrong tokens, all addresses
    std::uint64_t delayed() const { return mDelayed; }   ///< Auths that had to wait
    std::size_t addresses() const { return mEntries.size(); }

  private:
    struct Entry {
        unsigned failures = 0;
        Clock::time_point next; ///< the address's next check, not sooner
        Clock::time_point last; ///< its last failure
        bool waiting = false;   ///< an Auth of the address waits for `next`
    };
    static std::chrono::milliseconds waitAfter(unsigned failures);
    void makeRoom(Clock::time_point now);

    std::unordered_map<std::string, Entry> mEntries;
    std::uint64_t mFailures = 0, mDelayed = 0;
};

} // namespace bc::server::detail

#pragma once
// The one progress line of a long command (render, bench, study, tradeoff, reproduce), on stderr. Updates come
// far more often than a reader (or a CI log) wants them, per tile or per build, so they are rate-limited by wall
// time: on a terminal the line is redrawn in place at most every 0.25 s; elsewhere (a pipe, a file, mpirun) it
// is printed as plain lines at most every 2 s, plus each phase's start and last state, so logs stay short.
#include <chrono>
#include <cstdio>
#include <functional>
#include <mutex>
#include <optional>
#include <string>

namespace canopy {

// Whether a progress update may be shown at `now`: the first time, then once `interval` has passed since the
// last one shown. The clock is the caller's, so tests pass times instead of waiting.
class RateLimit {
public:
    using Clock = std::chrono::steady_clock;
    explicit RateLimit(Clock::duration interval) : interval_(interval) {}
    bool due(Clock::time_point now);  // true starts the interval again
    void restart(Clock::time_point now) { last_ = now; }

private:
    Clock::duration interval_;
    std::optional<Clock::time_point> last_;
};

// A progress line written to `out`: redrawn in place on a terminal, else as plain lines. Thread-safe: a render's
// tiles report from every worker.
class ProgressLine {
public:
    using Clock = RateLimit::Clock;
    static constexpr Clock::duration kTerminalInterval = std::chrono::milliseconds(250);
    static constexpr Clock::duration kPlainInterval = std::chrono::seconds(2);

    ProgressLine(std::FILE* out, bool terminal, std::function<Clock::time_point()> now = Clock::now);
    // Text put before every update (reproduce's paper and section, over the bench or study it runs); "" for none.
    void set_context(std::string context);
    // A phase starts: shown at once (plain lines: after the previous phase's last state, if it was not shown).
    void phase(const std::string& text);
    // Shown when the rate limit allows; otherwise kept, and shown by the next phase or finish if still the last.
    void update(const std::string& text);
    // Shows the last state if it was not, and ends the line (a terminal's), before the command prints results.
    void finish();
    // Erases a terminal's line, so that text printed to stdout starts on a line of its own; the next update draws
    // it again. Plain lines are already whole lines: nothing to do.
    void clear();

private:
    void show(const std::string& text);  // under mutex_
    void show_pending();                 // under mutex_

    std::FILE* out_;
    bool terminal_;
    std::function<Clock::time_point()> now_;
    RateLimit limit_;
    std::string context_, pending_;
    bool drawn_ = false;  // a terminal line is open (not yet ended by a newline)
    std::mutex mutex_;
};

// The command's progress line, for the layers below the command that know what is being done.
namespace progress {

// Shows the command's progress on stderr, on rank 0 of a job, unless `quiet`. Until a command calls it (the
// library, tests), every call below does nothing.
void start(bool quiet);
bool shown();  // whether start() enabled it here: callers skip building text nobody sees
void set_context(std::string context);
void phase(const std::string& text);
void update(const std::string& text);
void finish();
void clear();

}  // namespace progress

}  // namespace canopy

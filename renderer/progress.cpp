#include "renderer/progress.h"

#include "renderer/distributed.h"

#include <unistd.h>

#include <memory>

namespace canopy {

bool RateLimit::due(Clock::time_point now) {
    if (last_ && now - *last_ < interval_) return false;
    last_ = now;
    return true;
}

ProgressLine::ProgressLine(std::FILE* out, bool terminal, std::function<Clock::time_point()> now)
    : out_(out), terminal_(terminal), now_(std::move(now)), limit_(terminal ? kTerminalInterval : kPlainInterval) {}

void ProgressLine::set_context(std::string context) {
    const std::lock_guard lock(mutex_);
    context_ = std::move(context);
}

void ProgressLine::phase(const std::string& text) {
    const std::lock_guard lock(mutex_);
    if (!terminal_) show_pending();  // the previous phase's end, which a log would otherwise never see
    show(text);
    limit_.restart(now_());
}

void ProgressLine::update(const std::string& text) {
    const std::lock_guard lock(mutex_);
    if (limit_.due(now_())) {
        show(text);
    } else {
        pending_ = text;
    }
}

void ProgressLine::finish() {
    const std::lock_guard lock(mutex_);
    show_pending();
    if (drawn_) std::fputc('\n', out_);
    drawn_ = false;
    std::fflush(out_);
}

void ProgressLine::clear() {
    const std::lock_guard lock(mutex_);
    if (!drawn_) return;
    std::fputs("\r\033[K", out_);
    std::fflush(out_);
    drawn_ = false;
}

void ProgressLine::show(const std::string& text) {
    const std::string line = context_.empty() ? text : context_ + ": " + text;
    // On a terminal "\033[K" clears what a longer previous line left to the right.
    if (terminal_) std::fprintf(out_, "\r%s\033[K", line.c_str());
    else std::fprintf(out_, "%s\n", line.c_str());
    std::fflush(out_);
    drawn_ = terminal_;
    pending_.clear();
}

void ProgressLine::show_pending() {
    if (!pending_.empty()) show(pending_);
}

namespace progress {

namespace {

std::unique_ptr<ProgressLine>& line() {
    static std::unique_ptr<ProgressLine> command_line;
    return command_line;
}

}  // namespace

// Open MPI hands ranks their stderr as a pipe, so under mpirun rank 0 prints plain lines.
void start(bool quiet) {
    if (quiet || !distributed::is_root()) line().reset();
    else line() = std::make_unique<ProgressLine>(stderr, isatty(fileno(stderr)) != 0);
}

bool shown() { return line() != nullptr; }

void set_context(std::string context) {
    if (line()) line()->set_context(std::move(context));
}

void phase(const std::string& text) {
    if (line()) line()->phase(text);
}

void update(const std::string& text) {
    if (line()) line()->update(text);
}

void finish() {
    if (line()) line()->finish();
}

void clear() {
    if (line()) line()->clear();
}

}  // namespace progress

}  // namespace canopy

// The progress line's rate limit and what it writes, on a clock the tests move by hand.
#include "renderer/progress.h"

#include <catch2/catch.hpp>

#include <cstdio>
#include <memory>
#include <string>

using namespace canopy;
using namespace std::chrono_literals;

namespace {

using Clock = RateLimit::Clock;

// A progress line into a temporary file, on a clock at `now`.
struct Written {
    std::unique_ptr<std::FILE, int (*)(std::FILE*)> file{std::tmpfile(), std::fclose};
    Clock::time_point now{};
    ProgressLine line;

    explicit Written(bool terminal) : line(file.get(), terminal, [this] { return now; }) {}

    std::string text() {
        std::fflush(file.get());
        std::rewind(file.get());
        std::string all;
        for (int c; (c = std::fgetc(file.get())) != EOF;) all += char(c);
        return all;
    }
};

}  // namespace

TEST_CASE("RateLimit lets the first update through, then one per interval", "[progress]") {
    RateLimit limit(250ms);
    const Clock::time_point t0{};
    CHECK(limit.due(t0));
    CHECK_FALSE(limit.due(t0 + 100ms));
    CHECK_FALSE(limit.due(t0 + 249ms));
    CHECK(limit.due(t0 + 250ms));
    CHECK_FALSE(limit.due(t0 + 400ms));  // the interval starts again at the update shown, not at the one refused
    CHECK(limit.due(t0 + 500ms));
    limit.restart(t0 + 1000ms);
    CHECK_FALSE(limit.due(t0 + 1100ms));
}

TEST_CASE("Plain lines: a phase's start and last state, and at most one line per 2 s between", "[progress]") {
    Written w(false);
    w.line.phase("build 1 of 100");
    for (int i = 2; i <= 100; ++i) {  // 100 updates over 3 s: one more line, at 2 s
        w.now += 30ms;
        w.line.update("build " + std::to_string(i) + " of 100");
    }
    w.line.phase("frame 1 of 2");  // the build phase's last state first
    w.line.update("frame 2 of 2");
    w.line.finish();
    CHECK(w.text() == "build 1 of 100\nbuild 68 of 100\nbuild 100 of 100\nframe 1 of 2\nframe 2 of 2\n");
}

TEST_CASE("Terminal: redrawn in place at most every 0.25 s, the last state shown, the line ended", "[progress]") {
    Written w(true);
    w.line.set_context("reproduce p, Table 1");
    w.line.phase("a");
    w.now += 100ms;
    w.line.update("b");  // too soon: kept
    w.now += 200ms;
    w.line.update("c");
    w.now += 10ms;
    w.line.update("d");  // too soon: shown by finish
    w.line.finish();
    CHECK(w.text() == "\rreproduce p, Table 1: a\033[K\rreproduce p, Table 1: c\033[K\rreproduce p, Table 1: d\033[K\n");
}

TEST_CASE("Terminal: clear erases the line before other output, the next update draws it again", "[progress]") {
    Written w(true);
    w.line.phase("a");
    w.line.clear();
    w.line.clear();  // nothing drawn: nothing to erase
    w.now += 1s;
    w.line.update("b");
    w.line.finish();
    w.line.finish();  // already ended
    CHECK(w.text() == "\ra\033[K\r\033[K\rb\033[K\n");
}

TEST_CASE("Without a command's start (the library, the tests) there is no progress line", "[progress]") {
    CHECK_FALSE(progress::shown());
}

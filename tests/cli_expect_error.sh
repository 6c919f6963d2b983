#!/usr/bin/env bash
# Runs a canopy command that must fail cleanly: non-zero exit, no crash (signal) or sanitizer report, and stderr
# that contains the expected text (the file, field or option at fault).
# usage: cli_expect_error.sh EXPECTED_TEXT COMMAND [ARGS...]
# EXPECT_STATUS (environment), when set: the exit status required (canopy: 2 usage errors, 1 input and run errors).
expected=$1; shift
stderr=$("$@" 2>&1 >/dev/null); status=$?
if [ "$status" -eq 0 ]; then echo "expected failure, got exit 0: $*"; exit 1; fi
if [ -n "${EXPECT_STATUS:-}" ] && [ "$status" -ne "$EXPECT_STATUS" ]; then echo "expected exit $EXPECT_STATUS, got $status: $*"; echo "$stderr"; exit 1; fi
if [ "$status" -ge 128 ]; then echo "crashed with status $status: $*"; echo "$stderr"; exit 1; fi
# Under the sanitizer presets a report (a leak on the error path, say) also exits non-zero: it must not pass.
if grep -qE "(Address|Leak|UndefinedBehavior|Thread)Sanitizer|runtime error:" <<<"$stderr"; then echo "sanitizer report: $*"; echo "$stderr"; exit 1; fi
if ! grep -qF -- "$expected" <<<"$stderr"; then echo "stderr lacks '$expected': $*"; echo "$stderr"; exit 1; fi
echo "ok: exit $status, '$expected' named"

#!/usr/bin/env bash
# A command given one bad output path among good ones must refuse it before any work: cli_expect_error.sh's checks,
# and FOLDER, where its good outputs point, still empty afterwards (a late refusal would have written them).
# usage: cli_writes_nothing.sh FOLDER EXPECTED_TEXT COMMAND [ARGS...]
folder=$1; shift
rm -rf "$folder" && mkdir -p "$folder" || exit 1
"$(dirname "$0")/cli_expect_error.sh" "$@" || exit 1
if [ -n "$(ls -A "$folder")" ]; then echo "wrote $(ls -A "$folder") before refusing: ${*:2}"; exit 1; fi

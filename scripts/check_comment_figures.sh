#!/usr/bin/env bash
# Lists comment lines in non-test C++ sources that quote a figure, a date, a commit id or an issue number,
# because those belong in docs/results.md (linked by section) and go stale in code comments.
# Usage: scripts/check_comment_figures.sh [--count] [--max N] [path...]
#   --count  print only the number of offending lines
#   --max N  exit 1 when more than N lines offend
set -euo pipefail
cd "$(dirname "$0")/.."

count_only=0
max=""
paths=()
while [[ $# -gt 0 ]]; do
    case "$1" in
        --count) count_only=1; shift ;;
        --max)
            [[ $# -ge 2 && "$2" =~ ^[0-9]+$ ]] || { echo "check_comment_figures: --max needs a number" >&2; exit 2; }
            max="$2"; shift 2 ;;
        -h|--help) sed -n '2,6p' "$0"; exit 0 ;;
        -*) echo "check_comment_figures: unknown option '$1'" >&2; exit 2 ;;
        *) paths+=("$1"); shift ;;
    esac
done
[[ ${#paths[@]} -gt 0 ]] || paths=(.)

# Every *.h and *.cpp under the given paths, skipping tests, fuzz corpora, build trees and vendored code.
mapfile -t files < <(find "${paths[@]}" \
    \( -name tests -o -name build -o -name 'build-*' -o -path '*/fuzz/corpus' -o -name .git -o -name _deps \
       -o -name third_party \) -prune -o \( -name '*.h' -o -name '*.cpp' \) -type f -print | sort)

COUNT_ONLY="$count_only" MAX="$max" python3 - "${files[@]}" <<'PY'
import os
import re
import sys

FIGURE = re.compile(r"""
      \b\d+(?:\.\d+)?x\b(?!\d)                    # a ratio: 0.87x, 2x (but not 4x4)
    | \b\d+(?:\.\d+)?\s?(?:ms|ns|us|µs)\b          # a time
    | \b\d+\.\d+\s?%                               # a decimal percentage
    | \b(?:19|20)\d\d-\d\d(?:-\d\d)?\b             # an ISO date
    | \b\d{1,2}:\d\d\s?UTC\b                       # a clock time
    | \b(?:Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]*\.?\s+\d{1,2},?\s+(?:19|20)\d\d\b
    | \b\d{1,2}\s+(?:Jan|Feb|Mar|Apr|May|Jun|Jul|Aug|Sep|Oct|Nov|Dec)[a-z]*\s+(?:19|20)\d\d\b
    | \b(?=[0-9a-f]*\d)(?=[0-9a-f]*[a-f])[0-9a-f]{7,40}\b   # a commit id
    | \b(?:issue|issues|PR|pull\ request)\s?\#?\d+\b         # an issue number
    | (?<![\w&])\#\d+\b                            # #55
""", re.VERBOSE | re.IGNORECASE)


def comment_lines(text):
    """Yields (line number, comment text on that line), skipping string and character literals."""
    i, n, line = 0, len(text), 1
    pieces = {}
    state = "code"
    while i < n:
        c = text[i]
        if c == "\n":
            line += 1
            if state == "line":
                state = "code"
            i += 1
            continue
        if state == "code":
            if text.startswith("//", i):
                state = "line"; i += 2; continue
            if text.startswith("/*", i):
                state = "block"; i += 2; continue
            raw = re.match(r'R"([^()\\ ]{0,16})\(', text[i:i + 20])
            if raw and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
                end = text.find(")" + raw.group(1) + '"', i)
                end = n if end < 0 else end + len(raw.group(1)) + 2
                line += text.count("\n", i, end)
                i = end
                continue
            if c in "\"'":
                if c == "'" and i > 0 and text[i - 1].isalnum():   # digit separator: 1'000'000
                    i += 1; continue
                j = i + 1
                while j < n and text[j] != c and text[j] != "\n":
                    j += 2 if text[j] == "\\" else 1
                i = j + 1
                continue
            i += 1
            continue
        if state == "block" and text.startswith("*/", i):
            state = "code"; i += 2; continue
        pieces.setdefault(line, []).append(c)
        i += 1
    for number in sorted(pieces):
        yield number, "".join(pieces[number])


def main(files):
    hits = []
    for path in files:
        with open(path, encoding="utf-8", errors="replace") as handle:
            text = handle.read()
        source_lines = text.split("\n")
        for number, comment in comment_lines(text):
            if FIGURE.search(comment):
                hits.append(f"{os.path.normpath(path)}:{number}: {source_lines[number - 1].strip()}")
    if os.environ.get("COUNT_ONLY") == "1":
        print(len(hits))
    else:
        for hit in hits:
            print(hit)
        print(f"{len(hits)} comment line(s) quote a figure, date, commit id or issue number", file=sys.stderr)
    limit = os.environ.get("MAX", "")
    return 1 if limit and len(hits) > int(limit) else 0


sys.exit(main(sys.argv[1:]))
PY

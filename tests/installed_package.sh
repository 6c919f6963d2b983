#!/usr/bin/env bash
# canopy as a consumer gets it: installed into a fresh prefix, examples/ configured and built against it with
# find_package(canopy), cast_rays run on a small OBJ, and (given a Python) the installed module imported.
#   usage: installed_package.sh BUILD_DIR EXAMPLES_DIR WORK_DIR [PYTHON]
# CONSUMER_CXX_FLAGS: flags for the consumer's compiler (the sanitizers of a sanitized build);
# PYTHON_SANITIZER_ENV: NAME=VALUE pairs, ';'-separated, for the Python import alone.
set -euo pipefail
build=$1 examples=$2 work=$3 python=${4:-}
rm -rf "$work"
mkdir -p "$work"
cmake --install "$build" --prefix "$work/prefix" >/dev/null
cmake -S "$examples" -B "$work/build" -G Ninja -DCMAKE_PREFIX_PATH="$work/prefix" \
      -DCMAKE_CXX_FLAGS="${CONSUMER_CXX_FLAGS:-}" >/dev/null
cmake --build "$work/build" >/dev/null
printf 'v -1 -1 0\nv 1 -1 0\nv 1 1 0\nv -1 1 0\nv 0 0 1\nf 1 2 5\nf 2 3 5\nf 3 4 5\nf 4 1 5\nf 1 3 2\nf 1 4 3\n' >"$work/pyramid.obj"
"$work/build/cast_rays" "$work/pyramid.obj" sbvh
if [ -n "$python" ]; then
  IFS=';' read -r -a python_env <<<"${PYTHON_SANITIZER_ENV:-}"
  env "${python_env[@]}" PYTHONPATH="$(echo "$work"/prefix/lib/python3*/dist-packages)" "$python" -c "import canopy; print('python:', sorted(canopy.builders()))"
fi

#!/usr/bin/env bash
# The Python package as pip users get it: a wheel built by `python -m build --no-isolation --wheel` and installed
# into a fresh venv, then `pip install --no-build-isolation .` into another. From a folder outside the checkout,
# with PYTHONPATH unset, each venv imports canopy from its own site-packages, its _canopy and libcanopy resolve no
# library inside the checkout (ldd), and the wheel's venv passes tests/python.
#   usage: python_package.sh SOURCE_DIR WORK_DIR PYTHON
# PYTHON: the interpreter to package for, with build, venv, pip, setuptools, wheel, numpy and pytest (Debian's
# /usr/bin/python3 after scripts/setup.sh). Both builds reuse the CMake folder build-python/ (setup.py).
set -euo pipefail
source_dir=$(cd "$1" && pwd) work=$2 python=$3
unset PYTHONPATH
rm -rf "$work"
mkdir -p "$work"
work=$(cd "$work" && pwd)
outside=$(mktemp -d)
trap 'rm -rf "$outside"' EXIT

# run LOG COMMAND...: the command's output goes to LOG, whose end is shown if it fails.
run() {
  local log=$1; shift
  "$@" >"$log" 2>&1 || { echo "FAIL: $* (last lines of $log):" >&2; tail -40 "$log" >&2; exit 1; }
}

# check_installed VENV: canopy imports from VENV, the module finds libcanopy beside it through the RPATH $ORIGIN,
# and neither library resolves anything else inside the checkout (the venv itself may lie in the build tree).
check_installed() {
  local venv=$1 package library rpath
  package=$(cd "$outside" && "$venv/bin/python" -c 'import canopy, os; print(os.path.dirname(canopy.__file__))')
  case "$package" in
    "$venv"/*) echo "canopy.__file__ in $package" ;;
    *) echo "FAIL: canopy imported from $package, not from $venv" >&2; exit 1 ;;
  esac
  rpath=$(readelf -d "$package"/_canopy*.so | grep -E 'R(UN)?PATH')
  echo "$rpath"
  [[ $rpath == *"[\$ORIGIN]" ]] ||
    { echo "FAIL: the module's RPATH is not \$ORIGIN" >&2; exit 1; }
  for library in "$package"/_canopy*.so "$package"/libcanopy.so.*; do
    echo "ldd ${library#"$venv"/}:"
    ldd "$library" | tee "$work/ldd.txt" | sed 's/^/  /'
    if awk -v src="$source_dir/" -v venv="$venv/" '
         /not found/ { bad = 1 }
         $2 == "=>" && index($3, src) == 1 && index($3, venv) != 1 { bad = 1 }
         END { exit !bad }' "$work/ldd.txt"; then
      echo "FAIL: $library resolves a library inside $source_dir or none" >&2; exit 1
    fi
  done
  ldd "$package"/_canopy*.so >"$work/ldd.txt"
  grep -qF "=> $package/libcanopy.so." "$work/ldd.txt" ||
    { echo "FAIL: the module does not load the libcanopy beside it" >&2; exit 1; }
}

start=$SECONDS
run "$work/build_wheel.log" env -C "$source_dir" "$python" -m build --no-isolation --wheel --outdir "$work/dist"
wheel=$(echo "$work"/dist/canopy-*.whl)
echo "wheel: ${wheel##*/} ($((SECONDS - start)) s)"
run "$work/venv_wheel.log" "$python" -m venv --system-site-packages "$work/venv-wheel"
run "$work/install_wheel.log" "$work/venv-wheel/bin/pip" install --no-index "$wheel"
check_installed "$work/venv-wheel"
(cd "$outside" && "$work/venv-wheel/bin/python" -m pytest -q -p no:cacheprovider "$source_dir/tests/python")

start=$SECONDS
run "$work/venv_pip.log" "$python" -m venv --system-site-packages "$work/venv-pip"
run "$work/pip_install.log" env -C "$source_dir" "$work/venv-pip/bin/pip" install --no-index --no-build-isolation .
echo "pip install --no-build-isolation .: $((SECONDS - start)) s"
check_installed "$work/venv-pip"
(cd "$outside" && "$work/venv-pip/bin/python" -c "import canopy; print('builders:', sorted(canopy.builders()))")

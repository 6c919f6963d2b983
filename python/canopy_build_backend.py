"""pyproject.toml's PEP 517 backend: setuptools', asking for cmake, ninja and pybind11 from PyPI only where the
machine has none of its own.

Debian's cmake, ninja-build and pybind11-dev are no Python distributions, so fixed requirements on them would stop
`python -m build --no-isolation` and make an isolated build fetch copies of tools the machine already has.
"""
import importlib.util
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import build_meta as _setuptools
from setuptools.build_meta import *  # noqa: F401,F403  (every hook this module does not change)

CMAKE_MINIMUM = (3, 22)  # cmake_minimum_required of CMakeLists.txt


def _cmake_found():
    cmake = shutil.which("cmake")
    if not cmake:
        return False
    match = re.search(r"(\d+)\.(\d+)", subprocess.run([cmake, "--version"], capture_output=True, text=True).stdout)
    return bool(match) and tuple(int(n) for n in match.groups()) >= CMAKE_MINIMUM


def _pybind11_found():
    """An importable pybind11, or a CMake package of it where find_package looks (Debian: /usr/lib/cmake)."""
    if importlib.util.find_spec("pybind11"):
        return True
    prefixes = {sys.prefix, sys.base_prefix, "/usr", "/usr/local", *os.environ.get("CMAKE_PREFIX_PATH", "").split(os.pathsep)}
    return any(any(Path(prefix).glob(f"{folder}/pybind11Config.cmake"))
               for prefix in prefixes if prefix
               for folder in ("lib/cmake/pybind11", "lib/*/cmake/pybind11", "share/cmake/pybind11"))


def _missing_build_tools():
    missing = []
    if not _cmake_found():
        missing.append("cmake>=3.22")
    if not shutil.which("ninja"):
        missing.append("ninja")
    if not _pybind11_found():
        missing.append("pybind11>=2.10")
    return missing


def get_requires_for_build_wheel(config_settings=None):
    return _setuptools.get_requires_for_build_wheel(config_settings) + _missing_build_tools()


def get_requires_for_build_editable(config_settings=None):
    return _setuptools.get_requires_for_build_editable(config_settings) + _missing_build_tools()

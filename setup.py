"""The Python package canopy, built by CMake: `pip install .` or `python -m build --wheel` from the checkout.

build_ext configures build-python/ (Release, host ISA: the release preset's flags), builds the module _canopy and
libcanopy, installs CMake's component python_package (python/CMakeLists.txt) and copies it into the package.
CMAKE_ARGS adds configure options, e.g. CMAKE_ARGS=-DCANOPY_NATIVE=OFF for a wheel other CPUs can run.
"""
import os
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

from setuptools import Extension, setup
from setuptools.command.build_ext import build_ext

ROOT = Path(__file__).resolve().parent
# At the depth of the release preset's build/: ccache rewrites paths relative to the checkout (CCACHE_BASEDIR), so
# only a build folder as deep as build/ compiles to the same command lines and reuses that build's objects.
BUILD_DIR = ROOT / "build-python"


def project_version():
    """The version of project() in the top-level CMakeLists.txt."""
    match = re.search(r"project\(\s*canopy\s+VERSION\s+([0-9][0-9.]*)", (ROOT / "CMakeLists.txt").read_text())
    if not match:
        raise RuntimeError("setup.py: no project(canopy VERSION x.y.z) in CMakeLists.txt")
    return match.group(1)


def cached_generator():
    """The generator an earlier configure of BUILD_DIR chose, which CMake does not let a later one change."""
    cache = BUILD_DIR / "CMakeCache.txt"
    if cache.exists():
        match = re.search(r"^CMAKE_GENERATOR:INTERNAL=(.*)$", cache.read_text(), re.MULTILINE)
        if match:
            return match.group(1)
    return None


class CMakeExtension(Extension):
    """An extension CMake builds: setuptools compiles no sources of its own."""

    def __init__(self, name):
        super().__init__(name, sources=[])


class CMakeBuild(build_ext):
    def build_extension(self, ext):
        target = Path(self.get_ext_fullpath(ext.name))
        configure = ["cmake", "-S", str(ROOT), "-B", str(BUILD_DIR), "-DCMAKE_BUILD_TYPE=Release",
                     "-DCANOPY_NATIVE=ON", "-DCANOPY_TESTS=OFF", "-DCANOPY_FUZZ=OFF", "-DCANOPY_MPI=OFF",
                     "-DCANOPY_PYTHON=ON", f"-DPython_EXECUTABLE={sys.executable}"]
        ninja = shutil.which("ninja")
        generator = cached_generator() or ("Ninja" if ninja else None)
        if generator:
            configure += ["-G", generator]
        if generator == "Ninja" and ninja:
            # An earlier build's ninja may have lived in a deleted isolated build environment.
            configure.append(f"-DCMAKE_MAKE_PROGRAM={ninja}")
        try:
            import pybind11
            configure.append(f"-Dpybind11_DIR={pybind11.get_cmake_dir()}")
        except ImportError:
            pass  # CMake finds a system's pybind11 (Debian's pybind11-dev) by itself
        configure += shlex.split(os.environ.get("CMAKE_ARGS", ""))
        jobs = self.parallel or os.environ.get("CMAKE_BUILD_PARALLEL_LEVEL") or os.cpu_count() or 1
        staging = Path(self.build_temp).resolve() / "python_package"
        shutil.rmtree(staging, ignore_errors=True)
        for command in (configure,
                        ["cmake", "--build", str(BUILD_DIR), "--target", "canopy_python", "--parallel", str(jobs)],
                        ["cmake", "--install", str(BUILD_DIR), "--component", "python_package",
                         "--prefix", str(staging)]):
            print(" ".join(shlex.quote(c) for c in command), flush=True)
            subprocess.run(command, check=True)

        built = sorted(p.name for p in (staging / "canopy").glob("_canopy*"))
        if built != [target.name]:
            raise RuntimeError(f"setup.py: CMake built {built}, but {sys.executable} imports {target.name}")
        # The .py files come from build_py; the module and libcanopy go beside them.
        target.parent.mkdir(parents=True, exist_ok=True)
        for path in (staging / "canopy").iterdir():
            if path.suffix != ".py":
                shutil.copy2(path, target.parent / path.name)


setup(
    version=project_version(),
    packages=["canopy"],
    package_dir={"canopy": "python/canopy"},
    ext_modules=[CMakeExtension("canopy._canopy")],
    cmdclass={"build_ext": CMakeBuild},
    # setuptools' own build/ would land inside the release preset's CMake build folder.
    options={"build": {"build_base": "build-python/setuptools"}},
    zip_safe=False,
)

"""A wheel that starts warm: the build compiles the service's kernels into the wheel.

Everything about the project is in pyproject.toml; this file only adds a step to
``build_py``. After the sources are copied into the build directory, ``ezcompanion
compile`` runs there (a subprocess, on the build's own Python, with the build directory
first on its path), so that numba's cache of the service's kernels lands inside the
package (``ezcompanion/guidance/__pycache__/numba-<digest>/``) and ships in the wheel.
``pip install .`` then takes the compile (some 25 to 50 s on a 2-core machine) and the
first ``ezcompanion run`` loads the kernels instead (under a second).

The cache is found wherever the package is installed (``ezcompanion/guidance/_jit.py``),
and used only where numba's own checks pass: the same numba version, CPU model and
features, Python, and the same sources. A wheel built on one machine and installed on
another CPU compiles on its first run, as any install did before.

Skipped for an editable install (``pip install -e``: ``make`` runs ``ezcompanion compile``
itself) and when ``EZCOMPANION_BUILD_COMPILE=0`` (the wheel then carries no cache).
"""

from __future__ import annotations

import glob
import os
import shutil
import subprocess
import sys

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildWithKernels(build_py):
    """``build_py``, then the service's kernels compiled into the built package."""

    def run(self) -> None:
        super().run()
        if getattr(self, "editable_mode", False):
            return
        # a build directory used before (pip builds in the source tree's build/) may hold
        # the caches of earlier builds: only the one compiled now ships
        caches = os.path.join(self.build_lib, _CACHES, "numba-*")
        for cache in glob.glob(caches):
            shutil.rmtree(cache)
        if os.environ.get("EZCOMPANION_BUILD_COMPILE", "1") == "0":
            return
        # compiled, into the package's own cache directory, whatever this shell says
        dropped = ("NUMBA_CACHE_DIR", "EZCOMPANION_JIT", "NUMBA_DISABLE_JIT")
        env = {key: value for key, value in os.environ.items() if key not in dropped}
        # the built package first on the path, before what the build's environment puts
        # there (pip's isolated build finds its packages through PYTHONPATH)
        path = [os.path.abspath(self.build_lib), env.get("PYTHONPATH", "")]
        env["PYTHONPATH"] = os.pathsep.join(entry for entry in path if entry)
        env["PYTHONDONTWRITEBYTECODE"] = "1"  # the kernels' cache only, no .pyc files
        # run in the build directory: `python -c` puts its working directory first on the
        # path, and the source tree's own package must not be the one compiled
        subprocess.run([sys.executable, "-c", _COMPILE], env=env, cwd=self.build_lib, check=True)
        if not glob.glob(caches):
            raise RuntimeError(f"the kernels were compiled, but not into {caches}")


_CACHES = os.path.join("ezcompanion", "guidance", "__pycache__")  # numba-<digest>/ in it
_COMPILE = "from ezcompanion.commands import run_compile; raise SystemExit(run_compile())"


setup(cmdclass={"build_py": BuildWithKernels})

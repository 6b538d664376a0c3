"""Installing nscd compiles the main job's kernels ahead of time (numba, for this machine).

The metadata is in ``pyproject.toml``; this file adds one step to the build: after the
sources are in place (``build_py``), ``python -m nscd.precompile --store`` compiles the
kernels the main job needs into the package's compiled store ``nscd/_compiled``
(:mod:`nscd._jit`), so that the first run after installing does not compile them. It runs
with the build's interpreter, whose packages ``[build-system] requires`` lists; a failure
(it needs nothing but nscd's own dependencies) is reported and leaves the install as it
would be without it: the kernels then compile at their first call.
"""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py


class BuildWithCompiledStore(build_py):
    """``build_py``, then the compiled store of the built package (or, in an editable
    install, of the sources)."""

    def run(self) -> None:
        super().run()
        root = Path(__file__).resolve().parent if getattr(self, "editable_mode", False) else Path(self.build_lib)
        # the build's own packages may be on PYTHONPATH (pip's isolated build environment)
        path = os.pathsep.join(p for p in (str(root), os.environ.get("PYTHONPATH", "")) if p)
        env = {**os.environ, "PYTHONPATH": path, "OPENBLAS_NUM_THREADS": "1"}
        env.pop("NUMBA_DISABLE_JIT", None)
        done = subprocess.run([sys.executable, "-m", "nscd.precompile", "--store"], env=env, cwd=root,
                              stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        if done.returncode:
            print(f"nscd: the kernels were not compiled ahead of time; they compile at their first call.\n"
                  f"{done.stdout[-2000:]}", file=sys.stderr)
        else:
            print(done.stdout.strip(), file=sys.stderr)


setup(cmdclass={"build_py": BuildWithCompiledStore})

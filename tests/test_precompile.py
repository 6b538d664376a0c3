"""The compiled store: installing nscd compiles the main job's kernels ahead of time.

Run as an install and a user would, on a copy of the package (its store is written beside
its sources): the install's step ``python -m nscd.precompile --store``, then the main job
(``examples/single_block/free_rocking.py``) in a fresh process with an empty numba cache
folder, every numba compilation it makes recorded. It must compile nothing. Then one source
file of the copy is edited (a comment added): the store, stamped with the package's sources,
must no longer be used — the main job compiles its kernels again rather than run machine
code of other sources. Slow (the engine compiled from scratch twice: about a minute and a half).
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "single_block" / "free_rocking.py"

# In the child: run the example, then compile one new function (``probe``: the recording
# works), and print the kernels numba compiled from Python (a kernel compiled as the callee
# of another is part of its caller's compilation).
RECORD = """
import json, runpy, sys
import numba
from numba.core import event
compiled, depth = [], [0]
class Listener(event.Listener):
    def on_start(self, ev):
        depth[0] += 1
    def on_end(self, ev):
        depth[0] -= 1
        if depth[0] == 0:
            f = ev.data["dispatcher"].py_func
            compiled.append(f.__module__ + "." + f.__qualname__)
event.register("numba:compile", Listener())
sys.argv = sys.argv[1:]
runpy.run_path(sys.argv[0], run_name="__main__")
def probe(x):
    return x + 1
numba.njit(probe)(1)
print(json.dumps(compiled))
"""


def _compiled_by(example: list[str], package_root: Path, cache: Path, cwd: Path) -> list[str]:
    """The kernels ``example`` (a script and its arguments) compiles (``probe`` last) with
    ``package_root`` on its path and ``cache`` as numba's cache folder."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache), "PYTHONPATH": str(package_root),
           "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    env.pop("NUMBA_DISABLE_JIT", None)
    run = subprocess.run([sys.executable, "-c", RECORD, *example], env=env, check=True, capture_output=True,
                         text=True, cwd=cwd)
    return json.loads(run.stdout.strip().splitlines()[-1])


def _compiled_by_the_main_job(package_root: Path, cache: Path, out: Path) -> list[str]:
    """The kernels the main job compiles (``probe`` last)."""
    return _compiled_by([str(EXAMPLE), "--out", str(out)], package_root, cache, package_root)


@pytest.mark.slow
def test_main_job_compiles_nothing_after_the_install_and_again_after_an_edit(tmp_path):
    root = tmp_path / "installed"
    shutil.copytree(ROOT / "nscd", root / "nscd", ignore=shutil.ignore_patterns("__pycache__", "_compiled"))
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "unused"), "PYTHONPATH": str(root),
           "OPENBLAS_NUM_THREADS": "1"}
    env.pop("NUMBA_DISABLE_JIT", None)
    subprocess.run([sys.executable, "-m", "nscd.precompile", "--store"], env=env, check=True, capture_output=True,
                   cwd=root)
    assert any((root / "nscd" / "_compiled").glob("nscd.compiled_step.plain_steps.*.nbc"))
    assert not any((tmp_path / "unused").rglob("*.nbi")), "the store's build wrote into numba's cache"

    compiled = _compiled_by_the_main_job(root, tmp_path / "cache1", tmp_path / "out1")
    assert compiled == ["__main__.probe"], f"the main job still compiles {compiled[:-1]}"

    stepper = root / "nscd" / "stepper.py"
    stepper.write_text(stepper.read_text() + "\n# edited after the install\n")
    compiled = _compiled_by_the_main_job(root, tmp_path / "cache2", tmp_path / "out2")
    assert "nscd.compiled_step.plain_steps" in compiled, f"an edited package ran its store: {compiled}"



@pytest.mark.slow
def test_precompile_all_leaves_the_3d_trilith_and_an_arch_nothing_to_compile(tmp_path):
    """``python -m nscd.precompile --all`` compiles the engine's other families of kernels
    into numba's cache: the examples of the LNEC trilith (3D, a driven table, stepped by a
    Simulator) and of an arch's collapse load factor (the proximal point) then compile nothing.
    Slow (about two minutes of compilation)."""
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT),
           "OPENBLAS_NUM_THREADS": "1"}
    env.pop("NUMBA_DISABLE_JIT", None)
    subprocess.run([sys.executable, "-m", "nscd.precompile", "--all"], env=env, check=True, capture_output=True)
    for example in ([str(ROOT / "examples" / "trilith" / "lnec_trilith.py"), "--cycles", "2"],
                    [str(ROOT / "examples" / "masonry" / "arch_collapse.py")]):
        compiled = _compiled_by(example, ROOT, tmp_path / "cache", tmp_path)
        assert compiled == ["__main__.probe"], f"{Path(example[0]).name} still compiles {compiled[:-1]}"

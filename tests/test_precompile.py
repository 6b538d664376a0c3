"""The install step ``python -m nscd.precompile`` compiles every kernel the main job needs.

Run as a user would: in fresh processes sharing an empty numba cache folder, the step,
then the main job (``examples/single_block/free_rocking.py``) with every numba
compilation it makes recorded. Slow (it compiles the engine from scratch: tens of seconds).
"""
from __future__ import annotations

import json
import os
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
sys.argv = [sys.argv[1], "--out", sys.argv[2]]
runpy.run_path(sys.argv[0], run_name="__main__")
def probe(x):
    return x + 1
numba.njit(probe)(1)
print(json.dumps(compiled))
"""


@pytest.mark.slow
def test_main_job_compiles_nothing_after_the_install_step(tmp_path):
    env = {**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "cache"), "PYTHONPATH": str(ROOT),
           "OPENBLAS_NUM_THREADS": "1", "MPLBACKEND": "Agg"}
    env.pop("NUMBA_DISABLE_JIT", None)
    subprocess.run([sys.executable, "-m", "nscd.precompile"], env=env, check=True, capture_output=True)
    run = subprocess.run([sys.executable, "-c", RECORD, str(EXAMPLE), str(tmp_path / "out")], env=env,
                         check=True, capture_output=True, text=True)
    compiled = json.loads(run.stdout.strip().splitlines()[-1])
    assert compiled == ["__main__.probe"], f"the main job still compiles {compiled[:-1]}"

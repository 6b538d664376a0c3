"""Fault injection: a checkpointing run and sweeps killed (SIGKILL) at random moments.

Each victim runs in a forked child process (the compiled kernels are already loaded, so a
kill can land anywhere in a few seconds of work, saves included) that the test kills after a
random delay drawn from a seeded generator. Whatever the moment:

* the checkpoint left on disk, if any, loads and is the exact beginning of an uninterrupted
  run (the engine is deterministic to the bit, so exact equality is the test);
* a resumed sweep gives the byte-identical CSV of an uninterrupted one.
"""
from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

import nscd
from nscd import sweep

pytestmark = pytest.mark.skipif(sys.platform != "linux", reason="forks and kills processes (Linux)")

SEEDS = [0, 1, 2, 3]


def killed_at_random(target, args, seed: int, span: tuple[float, float], after: Path | None = None) -> float:
    """Run ``target(*args)`` in a forked child (its own process group) and SIGKILL the group
    after a delay uniform in ``span`` (s), counted from when the file ``after`` exists if
    given; return the delay."""
    delay = float(np.random.default_rng(seed).uniform(*span))
    child = multiprocessing.get_context("fork").Process(target=_in_own_group, args=(target, args))
    child.start()
    deadline = time.monotonic() + 60  # generous: a loaded 2-core machine
    while after is not None and not after.exists() and child.is_alive() and time.monotonic() < deadline:
        time.sleep(0.01)
    time.sleep(delay)
    try:
        os.killpg(child.pid, signal.SIGKILL)  # the child and any pool workers it started
    except ProcessLookupError:  # finished before the kill
        pass
    child.join()
    return delay


def _in_own_group(target, args) -> None:
    os.setsid()
    target(*args)


# ------------------------------------------------------------------ a checkpointing run

def rocking_scene() -> nscd.Scene:
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1))
    scene.add_block(nscd.box(0.3, 1.2), position=(0.0, 0.6), angle=0.0, omega=0.8)
    scene.set_contact(friction=0.7, restitution=0.0)
    return scene


DT = 2e-3


def checkpointing_run(path: str) -> None:
    # checkpoint_every tiny: a save after nearly every step, so kills often land inside a save
    nscd.simulate(rocking_scene(), t_end=20.0, dt=DT, checkpoint=path, checkpoint_every=1e-6)


def test_a_killed_checkpointing_run_leaves_a_checkpoint_that_loads(tmp_path):
    nscd.simulate(rocking_scene(), t_end=10 * DT, dt=DT)  # kernels loaded before the fork
    loaded = []
    for seed in SEEDS:
        path = tmp_path / f"run{seed}.npz"
        killed_at_random(checkpointing_run, (str(path),), seed, span=(0.0, 1.0), after=path)
        loaded.append(nscd.load(path))  # raises if the kill left a damaged file
    reference = nscd.simulate(rocking_scene(), t_end=max(len(r.time) - 1 for r in loaded) * DT, dt=DT)
    for result in loaded:
        n = len(result.time)
        assert result.status == "running"
        np.testing.assert_array_equal(result.time, reference.time[:n])
        np.testing.assert_array_equal(result.q, reference.q[:n])
        np.testing.assert_array_equal(result.v, reference.v[:n])


# ------------------------------------------------------------------ sweeps

def jittered_square(x: int, delay: float) -> dict:
    """A cell taking ``delay`` s (so kills land between, during and after cells)."""
    time.sleep(delay)
    return {"square": x * x, "root": float(np.sqrt(x))}


def jittered_squares(cases: list[dict], on_result=None) -> list[dict]:
    """The batched form: ``on_result`` as each case finishes."""
    rows = []
    for k, case in enumerate(cases):
        rows.append(jittered_square(**case))
        if on_result is not None:
            on_result(k, rows[-1])
    return rows


PARAMS = {"x": list(range(16))}
MODES = {  # name: (keyword arguments of grid, kill window in s)
    "serial": (dict(func=jittered_square), (0.05, 0.6)),
    "pool": (dict(func=jittered_square, jobs=2), (0.3, 1.5)),
    "batched": (dict(func=jittered_squares, batch=True, chunks=2, jobs=2), (0.3, 1.5)),
}


def run_sweep(out: str, mode: str) -> None:
    import concurrent.futures as cf

    kwargs = dict(MODES[mode][0])
    jobs = kwargs.pop("jobs", None)
    executor = sweep.SerialExecutor() if jobs is None else cf.ProcessPoolExecutor(jobs)
    try:
        sweep.grid(params=PARAMS, out=out, fixed={"delay": 0.03}, executor=executor, progress=False, **kwargs)
    finally:
        executor.shutdown()


@pytest.mark.parametrize("mode", list(MODES))
def test_a_killed_sweep_resumes_to_the_uninterrupted_files(tmp_path, mode):
    reference = tmp_path / "reference.csv"
    run_sweep(str(reference), mode)
    for seed in SEEDS:
        out = tmp_path / f"m{seed}.csv"
        killed_at_random(run_sweep, (str(out), mode), seed, span=MODES[mode][1])
        if out.exists():
            sweep.Table.from_csv(out)  # what a kill leaves is a readable CSV
        run_sweep(str(out), mode)  # resume (in this process: nothing is killed now)
        assert out.read_bytes() == reference.read_bytes(), f"seed {seed}"
        assert not Path(str(out) + ".cells").exists()

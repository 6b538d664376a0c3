"""Quick-look films (nscd.plot.animate): frame counts of the written files, format errors."""
from __future__ import annotations

import math
import os
import subprocess
import sys
from pathlib import Path

import pytest

import nscd
from nscd.motion import OneSine

PIL = pytest.importorskip("PIL.Image")
pytest.importorskip("matplotlib")
ROOT = Path(__file__).resolve().parents[1]
T_END, DT = 0.2, 1e-3


def expected_frames(t_end: float, fps: float, speed: float) -> int:
    """Frames at 0, speed / fps, 2 speed / fps, ... <= t_end, plus t_end when it falls between."""
    whole = math.floor(t_end * fps / speed + 1e-9)
    return whole + 1 + (not math.isclose(whole * speed / fps, t_end, abs_tol=1e-12))


@pytest.fixture(scope="module")
def rocking() -> nscd.Result:
    scene = nscd.Scene()
    scene.add_base(nscd.box(2.0, 0.2), position=(0.0, -0.1), motion=OneSine(amplitude=4.0, omega=6.1))
    scene.add_block(nscd.box(0.5, 1.5), position=(0.0, 0.75), density=2500.0)
    return nscd.simulate(scene, t_end=T_END, dt=DT, store_impulses=True)


@pytest.mark.parametrize("fps, speed", [(20.0, 1.0), (25.0, 0.5), (30.0, 1.0)])
def test_gif_has_one_frame_per_film_time(rocking, tmp_path, fps, speed):
    path = rocking.animate(tmp_path / "run.gif", fps=fps, speed=speed)
    assert path == tmp_path / "run.gif"
    with PIL.open(path) as gif:
        assert gif.n_frames == expected_frames(T_END, fps, speed)
        assert gif.size == (640, 480)                  # 6.4 x 4.8 in at 100 dpi
    assert [p.name for p in tmp_path.iterdir()] == ["run.gif"]   # no partial file left


def test_3d_projected_outlines(tmp_path):
    scene = nscd.Scene(dim=3)
    scene.add_base(nscd.box(1.0, 1.0, 0.2), position=(0.0, 0.0, -0.1))
    scene.add_block(nscd.box(0.2, 0.3, 0.6), position=(0.0, 0.0, 0.3), density=2000.0)
    result = nscd.simulate(scene, t_end=0.1, dt=DT, store_impulses=True)
    for view in ("xz", "yz"):
        with PIL.open(result.animate(tmp_path / f"{view}.gif", fps=20.0, view=view)) as gif:
            assert gif.n_frames == expected_frames(0.1, 20.0, 1.0)
    with pytest.raises(ValueError, match="view == 'xy', must be one of"):
        result.animate(tmp_path / "xy.gif", view="xy")


def test_formats_and_arguments_are_checked_before_drawing(rocking, tmp_path, monkeypatch):
    from matplotlib import animation

    with pytest.raises(ValueError, match=r"must end with \.gif or \.mp4"):
        rocking.animate(tmp_path / "run.avi")
    with pytest.raises(ValueError, match="fps == 0.0, must be > 0"):
        rocking.animate(tmp_path / "run.gif", fps=0.0)
    with pytest.raises(ValueError, match="does not exist"):
        rocking.animate(tmp_path / "missing" / "run.gif")
    monkeypatch.setattr(animation.writers, "is_available", lambda name: False)
    with pytest.raises(ValueError, match="needs ffmpeg on the PATH"):
        rocking.animate(tmp_path / "run.mp4")
    assert not any(tmp_path.iterdir())


def test_nscd_animate_command(rocking, tmp_path):
    saved = rocking.save(tmp_path / "run.npz")
    env = {**os.environ, "PYTHONPATH": str(ROOT), "OPENBLAS_NUM_THREADS": "1"}
    run = subprocess.run([sys.executable, "-m", "nscd.cli", "animate", str(saved), "-o", "run.gif", "--fps", "20"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, run.stderr
    frames = expected_frames(T_END, 20.0, 1.0)
    assert run.stdout.strip() == f"{saved} -> run.gif ({frames} frames)"
    with PIL.open(tmp_path / "run.gif") as gif:
        assert gif.n_frames == frames
    bad = subprocess.run([sys.executable, "-m", "nscd.cli", "animate", str(saved), "-o", "run.avi"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=600)
    assert bad.returncode == 2 and bad.stderr.count("\n") == 1 and "unknown format '.avi'" in bad.stderr

"""Files are written atomically, checkpoints are checked before the first step, and a failed
save never costs a computed result."""
from __future__ import annotations

import numpy as np
import pytest

import nscd
from nscd import _atomic


def block_scene():
    scene = nscd.Scene()
    scene.add_base(nscd.box(3.0, 0.2), position=(0.0, -0.1))
    scene.add_block(nscd.box(0.5, 1.5), position=(0.0, 0.75), angle=0.0, density=2500.0)
    return scene


def test_an_interrupted_write_leaves_the_old_file_and_no_temporary(tmp_path):
    path = tmp_path / "a.txt"
    _atomic.write_text(path, "old\n")
    with pytest.raises(KeyboardInterrupt):
        with _atomic.replacing(path) as tmp:
            tmp.write_text("new, half wri")
            raise KeyboardInterrupt  # Ctrl-C (or a crash) in the middle of the write
    assert path.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.txt"]


def test_an_interrupted_result_save_keeps_the_previous_checkpoint(tmp_path, monkeypatch):
    first = nscd.simulate(block_scene(), t_end=0.003, dt=1e-3)
    path = first.save(tmp_path / "run.npz")
    second = nscd.simulate(block_scene(), t_end=0.005, dt=1e-3)

    def savez_then_die(handle, **arrays):
        handle.write(b"PK\x03\x04 half an archive")
        raise KeyboardInterrupt

    monkeypatch.setattr(np, "savez_compressed", savez_then_die)
    with pytest.raises(KeyboardInterrupt):
        second.save(path)
    monkeypatch.undo()
    kept = nscd.load(path)
    np.testing.assert_array_equal(kept.time, first.time)
    np.testing.assert_array_equal(kept.q, first.q)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]


def test_saved_result_loads_back_identically(tmp_path):
    result = nscd.simulate(block_scene(), t_end=0.01, dt=1e-3, checkpoint=tmp_path / "sub" / "run")
    loaded = nscd.load(tmp_path / "sub" / "run.npz")
    for name in ("time", "q", "v", "kinetic", "potential", "dissipated", "work_input"):
        np.testing.assert_array_equal(getattr(loaded, name), getattr(result, name))
    assert loaded.status == "finished" and loaded.body_names == result.body_names


def test_an_unwritable_checkpoint_is_refused_before_the_first_step(tmp_path, monkeypatch):
    (tmp_path / "file").write_text("a file, not a folder")

    def no_step(self):
        raise AssertionError("a step was taken before the checkpoint path was checked")

    monkeypatch.setattr(nscd.Simulator, "step", no_step)
    with pytest.raises(ValueError, match=r"checkpoint == '.*file/run.npz' cannot be written"):
        nscd.simulate(block_scene(), t_end=1.0, dt=1e-3, checkpoint=tmp_path / "file" / "run.npz")


def test_a_failed_save_warns_and_returns_the_result(tmp_path, monkeypatch):
    def disk_full(self, path):
        raise OSError(28, "No space left on device", str(path))

    monkeypatch.setattr(nscd.Result, "save", disk_full)
    with pytest.warns(RuntimeWarning, match=r"checkpoint '.*run.npz' could not be saved .*No space left"):
        result = nscd.simulate(block_scene(), t_end=0.01, dt=1e-3, checkpoint=tmp_path / "run.npz")
    assert result.status == "finished" and len(result.time) == 11


def test_sweep_files_are_replaced_atomically(tmp_path, monkeypatch):
    table = nscd.Table([{"a": 1, "b": 2.5}])
    path = tmp_path / "t.csv"
    table.to_csv(path)
    before = path.read_text()

    def die(self, *args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(type(path), "write_text", die)
    with pytest.raises(KeyboardInterrupt):
        nscd.Table([{"a": 3, "b": 4.5}]).to_csv(path)
    monkeypatch.undo()
    assert path.read_text() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.csv"]

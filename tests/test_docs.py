"""The documentation builds: user guide (docs/*.md) and the API reference generated from
the docstrings, with Sphinx's warnings as errors.

``docs/conf.py`` is nitpicky, so a cross-reference to an nscd name that does not exist
(``:func:`nscd.no_such_thing```, a renamed class in a docstring, a guide link to a missing
page or heading) fails here, as does reStructuredText a docstring breaks.
"""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_docs_build_without_warnings(tmp_path: Path) -> None:
    out = tmp_path / "html"
    command = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
               "-d", str(tmp_path / "doctrees"), str(ROOT / "docs"), str(out)]
    run = subprocess.run(command, cwd=ROOT, capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, (
        "the docs do not build with warnings as errors "
        f"({' '.join(command)}):\n{run.stderr[-6000:]}")
    # The reference was generated, not just the guide: every module has its page.
    for module in ("nscd.stepper", "nscd.scene", "nscd.rocking", "nscd.solver.core"):
        assert (out / "api" / f"{module}.html").is_file(), module

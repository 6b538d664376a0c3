"""Every Python snippet of the user guide (``docs/guide/*.md``) and of the README runs as written.

Each fenced ``python`` block is a complete script: it runs in a fresh interpreter, in a
temporary folder (files it writes land there), with this checkout's ``nscd`` and
matplotlib's Agg backend. A block preceded by the MyST comment line ``% slow`` is marked
slow (run with ``-m slow``). The snippets carry their own checks (``assert`` on published
numbers or on theory) where the guide states a number.
"""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
GUIDE = ROOT / "docs" / "guide"
_FENCE = re.compile(r"^(?P<marks>(?:% [a-z]+\n)*)```python\n(?P<code>.*?)^```$",
                    re.MULTILINE | re.DOTALL)


def _snippets() -> list:
    cases = []
    for page in [ROOT / "README.md", *sorted(GUIDE.glob("*.md"))]:
        text = page.read_text(encoding="utf-8")
        for match in _FENCE.finditer(text):
            line = text[:match.start("code")].count("\n") + 1
            marks = [pytest.mark.slow] if "% slow" in match.group("marks") else []
            cases.append(pytest.param(page, line, match.group("code"), marks=marks,
                                      id=f"{page.stem}:{line}"))
    return cases


SNIPPETS = _snippets()


def test_the_guide_has_snippets() -> None:
    assert len(SNIPPETS) >= 7, [p.id for p in SNIPPETS]


@pytest.mark.parametrize("page, line, code", SNIPPETS)
def test_snippet_runs(page: Path, line: int, code: str, tmp_path: Path) -> None:
    script = tmp_path / "snippet.py"
    script.write_text(code, encoding="utf-8")
    env = dict(os.environ, PYTHONPATH=str(ROOT), MPLBACKEND="Agg", OPENBLAS_NUM_THREADS="1")
    run = subprocess.run([sys.executable, str(script)], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=900)
    assert run.returncode == 0, (
        f"{page.relative_to(ROOT)}, snippet at line {line} failed:\n{run.stderr[-4000:]}")

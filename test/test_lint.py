"""``ruff check`` over every package, the tests and the scripts (configuration: ruff.toml)."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _ruff() -> list:
    exe = shutil.which('ruff') or str(Path(sys.executable).with_name('ruff'))
    return [exe]


def test_ruff_passes_on_the_repository():
    out = subprocess.run(_ruff() + ['check', '--no-cache', 'src', 'test', 'scripts'], cwd=ROOT,
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stdout[-6000:] + out.stderr[-2000:]


def test_ruff_finds_a_planted_error(tmp_path):
    """The check is live: the same configuration flags an unused import and a long line."""
    bad = tmp_path / 'bad.py'
    bad.write_text('import os\n' + 'x = "' + 'a' * 120 + '"\n')
    out = subprocess.run(_ruff() + ['check', '--no-cache', '--config',
                                    str(ROOT / 'ruff.toml'), str(bad)],
                         capture_output=True, text=True, timeout=300)
    assert out.returncode == 1
    assert 'F401' in out.stdout and 'E501' in out.stdout

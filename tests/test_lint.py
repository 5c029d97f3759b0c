"""The import and style rules of pyproject's [tool.ruff] hold everywhere: `ruff check` finds nothing."""

import subprocess
import sys


def test_ruff_check_passes(repo):
    res = subprocess.run([sys.executable, "-m", "ruff", "check", str(repo)], cwd=repo, capture_output=True, text=True,
                         timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr

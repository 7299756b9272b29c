"""The guide's Python example (docs/python.md) runs and prints what its comment says."""

import os
import re
import subprocess
import sys

from conftest import WORKSPACE


def test_readme_python_example():
    text = (WORKSPACE / "docs" / "python.md").read_text()
    code = re.search(r"```python\n(.*?)```", text, re.S).group(1)
    assert len(code.strip().splitlines()) == 5
    expected = re.search(r"# (\d+ [\d.]+)\s*$", code.strip()).group(1)
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=str(WORKSPACE), capture_output=True, text=True, timeout=120,
        env=dict(os.environ, PYTHONPATH=""),
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == expected

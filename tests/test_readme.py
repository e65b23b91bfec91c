"""Every ```python block of README.md runs on its own: the first code a reader copies must work.

Each block runs in a fresh namespace, in a temporary working directory (a block that writes
files writes them there).
"""
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parent.parent / "README.md"
BLOCKS = re.findall(r"^```python\n(.*?)^```", README.read_text(encoding="utf-8"), re.S | re.M)


def test_readme_has_python_blocks():
    assert BLOCKS, "README.md has no ```python blocks"


@pytest.mark.parametrize("k", range(len(BLOCKS)))
def test_readme_block_runs(k, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    exec(compile(BLOCKS[k], f"README.md, python block {k + 1}", "exec"),
         {"__name__": "__readme__"})


def test_readme_lists_every_module():
    """The "What is here" table names each sub-package's modules, all of them."""
    package = README.parent / "skfem_nem"
    rows = re.findall(r"^\| `skfem_nem\.(\w+)` \| (.*?) \|", README.read_text(encoding="utf-8"),
                      re.M)
    listed = {sub: set(re.findall(r"`(\w+)`", names)) for sub, names in rows}
    actual = {p.name: {m.stem for m in p.glob("*.py") if m.stem != "__init__"}
              for p in package.iterdir() if (p / "__init__.py").exists()}
    assert listed == actual

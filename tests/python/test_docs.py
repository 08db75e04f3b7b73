"""docs/python.md runs as it stands: its ```python blocks are executed in order, in one
namespace, from the repository root (so the documented example cannot rot)."""
import os
import re
from pathlib import Path

SOURCE = Path(os.environ.get("FLEXBENCH_SOURCE_DIR", Path(__file__).resolve().parents[2]))


def test_python_md_runs(monkeypatch, capsys):
    text = (SOURCE / "docs" / "python.md").read_text()
    blocks = re.findall(r"^```python\n(.*?)^```", text, flags=re.S | re.M)
    assert len(blocks) >= 3
    monkeypatch.chdir(SOURCE)
    namespace = {"__name__": "docs_python_md"}
    for i, code in enumerate(blocks):
        exec(compile(code, f"docs/python.md block {i + 1}", "exec"), namespace)
    out = capsys.readouterr().out
    assert "accepted" in out
    assert "['detector.threads=1']" in out


def test_readme_python_section_runs(monkeypatch, tmp_path):
    # The README's 'Use from Python' example, from a folder that looks like the repository's
    # root (it writes out/smoke).
    text = (SOURCE / "README.md").read_text()
    section = text[text.index("## Use from Python"):]
    code = re.search(r"^```python\n(.*?)^```", section, flags=re.S | re.M).group(1)
    for name in ("models", "scenarios"):
        (tmp_path / name).symlink_to(SOURCE / name)
    monkeypatch.chdir(tmp_path)
    namespace = {"__name__": "readme"}
    exec(compile(code, "README.md 'Use from Python'", "exec"), namespace)
    assert namespace["summary"]["overrides"] == ["seed=2"]
    assert namespace["summary"]["seed"] == 2
    assert namespace["T_est"].shape == (4, 4)

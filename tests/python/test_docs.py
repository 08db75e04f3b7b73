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


def _anchor(heading):
    # GitHub's heading ids: lower case, punctuation other than '-' and '_' dropped, spaces to '-'.
    return re.sub(r"[^\w\- ]", "", heading.strip().lower()).replace(" ", "-")


def test_links_between_readme_and_docs_resolve():
    # Text moves between the README and docs/; every relative link and #anchor must follow it.
    pages = [SOURCE / "README.md"] + sorted((SOURCE / "docs").glob("*.md"))
    anchors = {}
    for page in pages:
        text = re.sub(r"^```.*?^```", "", page.read_text(), flags=re.S | re.M)
        anchors[page.resolve()] = {_anchor(h) for h in re.findall(r"^#+ (.*)$", text, flags=re.M)}
    broken = []
    for page in pages:
        for link in re.findall(r"\]\(([^)\s]+)\)", page.read_text()):
            if re.match(r"[a-z]+:", link):
                continue
            path, _, anchor = link.partition("#")
            target = (page.parent / path).resolve() if path else page.resolve()
            if not target.exists():
                broken.append(f"{page.name}: {link} (no such file)")
            elif anchor and target.suffix == ".md" and anchor not in anchors.get(target, set()):
                broken.append(f"{page.name}: {link} (no such heading)")
    assert not broken, "\n".join(broken)

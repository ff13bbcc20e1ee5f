"""The README shows python/examples/launch.py as it is (tests/hil/test_package.py runs the file)."""

from pathlib import Path

REPO = Path(__file__).resolve().parents[2]


def test_readme_shows_the_example_verbatim():
    example = (REPO / "python" / "examples" / "launch.py").read_text()
    readme = (REPO / "README.md").read_text()
    assert f"```python\n{example}```" in readme, "README.md's python example differs from python/examples/launch.py"
    assert len(example.splitlines()) <= 20

"""Every Python example in the README and in the documentation pages (``docs/``) runs as written.

Each ```` ```python ```` block runs on its own, in a fresh namespace. A block that reads the
project's real recordings is preceded by the line ``<!-- example: needs eval_data -->``: it runs
from the repository root (its paths are relative to it) and skips outside CI, or fails in CI, when
``../shared/eval_data`` is absent, like the other tests on the recordings. A snippet that cannot run
on its own is fenced ```` ```py ```` instead (highlighted the same, not run), with the reason in the
text beside it. The Rust blocks are doctests of the crate (``src/lib.rs``).
"""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from eval_data import require

ROOT = Path(__file__).resolve().parents[2]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
FENCE = re.compile(
    r"^(?:<!-- example: (?P<marker>[^>]*?) -->\n)?```python\n(?P<code>.*?)^```$", re.S | re.M
)
#: What a marker may say, and what it needs.
MARKERS: dict[str, tuple[str, ...]] = {"needs eval_data": ()}


def _examples() -> list[tuple[str, int, str | None, str]]:
    found = []
    for page in PAGES:
        name = page.relative_to(ROOT).as_posix()
        for index, match in enumerate(FENCE.finditer(page.read_text())):
            found.append((name, index, match["marker"], match["code"]))
    return found


EXAMPLES = _examples()


def _count(page: str) -> int:
    return sum(1 for name, *_ in EXAMPLES if name == page)


def test_readme_has_examples() -> None:
    # The two set-up commands open the README, and its tour has a Python and a Rust example.
    text = (ROOT / "README.md").read_text()
    first_block = re.search(r"```bash\n(.*?)```", text, flags=re.S)
    assert first_block is not None
    assert "pip install . && lidarcal demo" in first_block[1]
    assert "bash scripts/check.sh" in first_block[1]
    assert _count("README.md") >= 1
    assert "```rust\n" in text


def test_docs_pages_have_examples() -> None:
    # The README's examples moved to these pages; a fence or pattern change must not drop them.
    expected = {
        "docs/index.md": 1,
        "docs/command_line.md": 1,
        "docs/calibrate_your_own_sensors.md": 1,
        "docs/checking.md": 1,
        "docs/methods/corner.md": 1,
        "docs/methods/poles.md": 1,
        "docs/methods/targetless.md": 1,
        "docs/methods/auto_and_rig.md": 1,
        "docs/building_blocks.md": 2,
        "docs/simulator.md": 1,
        "docs/results.md": 1,
        "docs/fleet.md": 1,
    }
    assert {page: min(_count(page), n) for page, n in expected.items()} == expected
    assert len(EXAMPLES) >= 12


def test_every_python_block_is_collected() -> None:
    # A ```python fence the pattern misses (indented, unterminated) would silently not run.
    for page in PAGES:
        fences = page.read_text().count("```python\n")
        assert fences == _count(page.relative_to(ROOT).as_posix()), page


def test_rust_blocks_are_doctests() -> None:
    # A page's Rust examples run only if src/lib.rs includes the page into its test-only docs.
    lib = (ROOT / "src" / "lib.rs").read_text()
    for page in PAGES:
        name = page.relative_to(ROOT).as_posix()
        if re.search(r"^```rust$", page.read_text(), flags=re.M):
            assert f'include_str!("../{name}")' in lib, f"{name} has Rust examples no doctest runs"


def test_readme_links_resolve() -> None:
    # mkdocs --strict checks the pages' links; the README's relative links are checked here.
    text = (ROOT / "README.md").read_text()
    for target in re.findall(r"\]\(([^)#]+)(?:#[^)]*)?\)", text):
        if not re.match(r"[a-z]+://", target):
            assert (ROOT / target).exists(), target


@pytest.mark.parametrize(
    ("page", "index", "marker", "code"),
    EXAMPLES,
    ids=[f"{page}-{index}" for page, index, _, _ in EXAMPLES],
)
def test_example_runs(
    page: str, index: int, marker: str | None, code: str, monkeypatch: pytest.MonkeyPatch
) -> None:
    if marker is not None:
        assert marker in MARKERS, f"unknown example marker {marker!r} in {page}"
        require(*MARKERS[marker])
        monkeypatch.chdir(ROOT)
    exec(compile(code, f"{page} python block {index}", "exec"), {})

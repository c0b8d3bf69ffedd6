"""The README's Python blocks run as written, its relative links resolve, and its commands match
CI's, so that the front page cannot drift from the code."""

import re
import tomllib
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
PAGES = [README, ROOT / "CHANGELOG.md", *sorted((ROOT / "docs").glob("*.md"))]

FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def _blocks(language: str) -> list[str]:
    return [body for lang, body in FENCE.findall(README.read_text()) if lang == language]


def test_readme_python_blocks_run(tmp_path, monkeypatch):
    blocks = _blocks("python")
    assert len(blocks) >= 2  # the quickstart and writing one's own demos
    monkeypatch.chdir(tmp_path)  # the snippets write files where they run
    namespace: dict[str, object] = {"__name__": "__readme__"}
    for block in blocks:  # in order, in one namespace: a later block uses an earlier one's names
        exec(compile(block, str(README), "exec"), namespace)
    assert (tmp_path / "my_demos.npz").is_file()


def test_readme_links_to_every_docs_page():
    links = set(LINK.findall(README.read_text()))
    unlinked = [p.name for p in PAGES[2:] if f"docs/{p.name}" not in links]
    assert not unlinked, f"README.md links to no {unlinked}"


@pytest.mark.parametrize("page", PAGES, ids=lambda p: p.name)
def test_relative_links_resolve(page):
    links = LINK.findall(page.read_text())
    missing = []
    for target in links:
        if re.match(r"[a-z]+:", target) or target.startswith("#"):  # https:, mailto:, anchors
            continue
        path = (page.parent / target.split("#")[0]).resolve()
        if not path.exists():
            missing.append(target)
    assert not missing, f"{page.name} links to paths that do not exist: {missing}"


def test_readme_test_commands_are_what_ci_runs():
    # .ci/run: its commands after the `cd` to the checkout, the README's block of them verbatim.
    lines = (ROOT / ".ci" / "run").read_text().strip().splitlines()
    ci_commands = lines[[ln.startswith("cd ") for ln in lines].index(True) + 1 :]
    assert ci_commands[0].startswith("python3 -m venv .venv")
    assert any("pytest" in command for command in ci_commands)
    assert ci_commands in [block.strip().splitlines() for block in _blocks("bash")]


def test_readme_main_command():
    main = "python3 -m venv .venv && .venv/bin/pip install -q -e . && .venv/bin/ilfo train"
    assert main in [line for block in _blocks("bash") for line in block.splitlines()]


def test_citation_version_is_the_package_version():
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    cff = (ROOT / "CITATION.cff").read_text()
    assert re.search(rf'^version: "?{re.escape(version)}"?$', cff, re.MULTILINE), version

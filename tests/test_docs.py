"""The docs site: its guides' Python blocks run as written, the command-line reference is the
parsers' current help, and `mkdocs build --strict` passes (no broken link, anchor or docstring).

A Python block that cannot run here (a fragment of a source file, a long training run) starts
with the line ``# not run: <why>``; it is the only exception."""

import importlib.util
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"
GUIDES = sorted(DOCS.glob("*.md"))  # the site's pages; the run folders' reports are not guides
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.MULTILINE | re.DOTALL)
NOT_RUN = "# not run:"


def _python_blocks(page: Path) -> list[str]:
    return [body for lang, body in FENCE.findall(page.read_text()) if lang == "python"]


def _pages_with_code() -> list[Path]:
    return [page for page in GUIDES if _python_blocks(page)]


def test_guides_have_code_to_run():
    run = {p.name for p in _pages_with_code() if any(_runs(b) for b in _python_blocks(p))}
    assert {"demos.md", "rl-code.md"} <= run, run


def _runs(block: str) -> bool:
    first = block.split("\n", 1)[0].strip()
    if first.startswith(NOT_RUN):
        assert first[len(NOT_RUN) :].strip(), f"a not-run block must say why: {first!r}"
        return False
    return True


@pytest.mark.parametrize("page", _pages_with_code(), ids=lambda p: p.name)
def test_guide_python_blocks_run(page, tmp_path, monkeypatch, request):
    monkeypatch.chdir(tmp_path)  # the blocks write files where they run
    if "stable_baselines3" in page.read_text():
        # torch's threads spin against the other test workers' on the same cores: one thread
        # does this page's few SAC updates in a tenth of the CPU time.
        import torch

        threads = torch.get_num_threads()
        torch.set_num_threads(1)
        request.addfinalizer(lambda: torch.set_num_threads(threads))
    namespace: dict[str, object] = {"__name__": f"__docs_{page.stem}__"}
    for block in filter(_runs, _python_blocks(page)):  # in order, in one namespace
        exec(compile(block, str(page), "exec"), namespace)


def _generator():
    path = ROOT / "scripts" / "gen_cli_reference.py"
    spec = importlib.util.spec_from_file_location("gen_cli_reference", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_is_the_parsers_help(monkeypatch):
    generator = _generator()
    monkeypatch.setenv("COLUMNS", "60")  # the page is the same in any terminal
    expected = generator.reference()
    assert "## `ilfo train`" in expected and "--demos" in expected
    assert (DOCS / "cli.md").read_text() == expected, (
        f"docs/cli.md differs from the parsers' help: regenerate it with {generator.COMMAND}"
    )


def test_mkdocs_build_strict(tmp_path):
    done = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},  # not mkdocs-material's notice
    )
    assert done.returncode == 0, done.stdout + done.stderr
    assert (tmp_path / "api" / "rewards" / "index.html").is_file()

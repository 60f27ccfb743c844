"""Every command in README.md runs as written (issue 15, item 8).

The commands of the fenced ``bash`` blocks are collected in order. Every ``spslidar`` command
must parse; the ``run``, ``snr`` and ``python -c`` commands of the tour run for real, from a
copy of the repository's shipped files, in one temporary working directory, in README order
(later commands may use files earlier ones wrote). ``reproduce``, ``sweep``, benchmark and
install commands take minutes or need the network: they are parsed here and run under
``pytest -m slow``.
"""

from __future__ import annotations

import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from spslidar.cli import build_parser, main

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _commands() -> list[str]:
    text = README.read_text(encoding="utf-8")
    out = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            line = line.strip()
            if line and not line.startswith("#"):
                out.append(line)
    return out


def _split(line: str) -> list[list[str]]:
    """A line's commands (``a && b``), each without its trailing comment."""
    parts = []
    for piece in line.split("&&"):
        words = shlex.split(piece, comments=True)
        if words:
            parts.append(words)
    return parts


COMMANDS = [words for line in _commands() for words in _split(line)]
FAST = {"run", "snr", "reconstruct", "calibrate"}


def _kind(words: list[str]) -> str:
    if words[0] == "spslidar":
        return "fast" if words[1] in FAST else "slow"
    if words[:2] == ["python", "-c"]:
        return "fast"
    return "slow"


def test_readme_has_commands():
    assert len(COMMANDS) > 15
    assert any(w[:2] == ["spslidar", "run"] for w in COMMANDS)


@pytest.mark.parametrize("words", [w for w in COMMANDS if w[0] == "spslidar"],
                         ids=lambda w: " ".join(w[1:4]))
def test_every_spslidar_command_parses(words):
    build_parser().parse_args(words[1:])


def test_every_referenced_file_exists_or_is_written_first():
    """Files a command reads exist in the repository, or an earlier command writes them."""
    written: set[str] = set()
    for words in COMMANDS:
        if words[0] == "python" and words[1] == "-c":
            written.update(re.findall(r"np\.save\('([^']+)'", words[2]))
            continue
        if words[0] == "python" and not words[1].startswith("-"):
            assert (ROOT / words[1]).is_file(), words
        written.update(words[i + 1] for i, w in enumerate(words) if w == "--save-ptu")
        written.update(words[i + 1].replace(".ptu", suffix) for i, w in enumerate(words)
                       if w == "--save-ptu" for suffix in ("_patterns.npy", "_code.npy"))
        if "--out" in words:
            written.update(f"{words[words.index('--out') + 1]}/{f}"
                           for f in ("truth.npy", "depth.npy", "valid.npy"))
        for flag in ("--config", "--scene", "--ptu", "--patterns", "--truth"):
            if flag in words:
                value = words[words.index(flag) + 1]
                if Path(value).suffix and flag != "--code":
                    assert (ROOT / value).is_file() or value in written, (flag, value)
        if words[:2] == ["spslidar", "sweep"]:
            assert (ROOT / words[2]).is_file(), words


def _workdir(tmp_path: Path) -> Path:
    for name in ("configs", "benchmarks"):
        shutil.copytree(ROOT / name, tmp_path / name)
    return tmp_path


def _execute(words: list[str], cwd: Path) -> None:
    if words[0] == "spslidar":
        assert main(words[1:]) == 0, words
    else:
        subprocess.run([sys.executable, *words[1:]], cwd=cwd, check=True)


def test_tour_commands_run_as_written(tmp_path, monkeypatch):
    """The run / snr / python -c commands, in README order, exit 0 and write their output."""
    cwd = _workdir(tmp_path)
    monkeypatch.chdir(cwd)
    for words in COMMANDS:
        if _kind(words) == "fast":
            _execute(words, cwd)
            if "--out" in words:
                out = cwd / words[words.index("--out") + 1]
                assert (out if words[1] == "calibrate" else out / "metrics.json").is_file()
            if "--save-ptu" in words:
                assert (cwd / words[words.index("--save-ptu") + 1]).is_file()


@pytest.mark.slow
def test_slow_commands_run_as_written(tmp_path, monkeypatch):
    """reproduce, sweep and the benchmarks (minutes): run with ``pytest -m slow``."""
    cwd = _workdir(tmp_path)
    monkeypatch.chdir(cwd)
    for words in COMMANDS:
        if words[0] == "pip" or words[:2] == ["python", "-m"] or words[0] == "pytest":
            continue  # installs, the docs build and the test suite itself
        if _kind(words) == "slow":
            _execute(words, cwd)


def test_python_blocks_run_as_written(tmp_path, monkeypatch):
    """The README's Python API blocks run as written (in a fresh working directory)."""
    blocks = re.findall(r"```python\n(.*?)```", README.read_text(encoding="utf-8"), flags=re.S)
    assert blocks, "the README shows the Python API"
    monkeypatch.chdir(_workdir(tmp_path))
    for code in blocks:
        exec(compile(code, "README.md", "exec"), {"__name__": "__readme__"})
    assert (tmp_path / "runs" / "api" / "metrics.json").is_file()

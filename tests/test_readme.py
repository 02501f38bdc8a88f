"""The README stays true: what it says about the package is checked against the package.

The lecture table against lectures/, exercises/ and solutions/; the grading modules and every graded task (the
grader table's columns) against the registry; every ``python -m course ...`` command and every option the
README's command block shows against the commands' own parsers; the explorers' lectures against the explorer
registry; the two start-here commands against the README's own set-up. Numbers that cannot be tested here (run
times) must be dated or name the command that made them: a test checks that the suite's timings are dated.
"""
import argparse
import re
import shlex
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
LECTURES = sorted(p.name for p in (ROOT / "lectures").glob("[0-9][0-9]_*.ipynb"))


def _section(title: str) -> str:
    start = README.index(title)
    end = README.find("\n## ", start + len(title))
    return README[start:end if end > 0 else None]


def test_the_lecture_table_lists_every_lecture_once():
    rows = re.findall(r"^\| (\d+) \| ([^|]+) \|.*\| ([^|]+) \| ([^|]+) \|$", _section("## What the course teaches"),
                      flags=re.M)
    numbers = [int(n) for n, *_ in rows]
    assert numbers == [int(name[:2]) for name in LECTURES], "the table's rows are the lectures, in order"
    for (n, title, run_all, status), name in zip(rows, LECTURES):
        words = name[3:-6].split("_")
        assert words[0].lower() in title.lower(), f"lecture {n}: {title!r} is not {name}"
        assert re.fullmatch(r"\d+ s|\d+ min( \d+ s)?", run_all.strip()), f"lecture {n}: Run All {run_all!r}"
        assert status.strip() == "ready"
        for folder in ("exercises", "solutions"):
            assert (ROOT / folder / name).is_file(), f"{folder}/{name} is missing"


def test_the_grading_modules_and_tasks_are_the_registry():
    from course.grading.registry import TASKS, _task_key
    modules = sorted(p.stem for p in (ROOT / "course" / "grading").glob("lecture[0-9][0-9].py"))
    assert modules == [f"lecture{int(name[:2]):02d}" for name in LECTURES]
    assert f"`{modules[0]}.py` … `{modules[-1]}.py`" in README
    header = next(line for line in README.splitlines() if line.startswith("student    notebook "))
    columns = header.split()[2:-1]                                       # the grader table's task columns
    assert columns == sorted(TASKS, key=_task_key), "the grader table's columns are the registered tasks"
    for task_id in TASKS:                                                 # every task is named somewhere
        assert re.search(rf"\b{re.escape(task_id)}\b", README)


def _command_block() -> list[str]:
    block = _section("## Command line").split("```bash\n", 1)[1].split("```", 1)[0]
    lines, joined = [], ""
    for line in block.splitlines():                                     # join continued lines
        joined += line.split("  #", 1)[0].rstrip().rstrip("\\") + " "
        if not line.rstrip().endswith("\\"):
            lines.append(joined.strip())
            joined = ""
    return [line for line in lines if line.startswith("python -m course")]


def test_every_command_is_in_the_command_block_and_every_shown_option_exists():
    from course.__main__ import COMMANDS
    from course.bench import BENCHES
    lines = _command_block()
    shown = {line.split()[3] for line in lines}
    assert set(COMMANDS) <= shown, f"commands missing from the README's block: {set(COMMANDS) - shown}"
    benches = {line.split()[4] for line in lines if line.split()[3] == "bench"}
    assert set(BENCHES) <= benches, f"benchmarks missing from the README's block: {set(BENCHES) - benches}"
    for line in lines:
        words = line.split()
        command = words[3]
        assert command in COMMANDS, f"{line!r}: no command {command!r}"
        options = set(re.findall(r"(?<![\w-])(--[a-z][a-z0-9-]*)", line))
        if not options or command == "lab":                            # lab passes the rest to jupyter lab
            continue
        parser = _parser(command, words[4] if command == "bench" else None)
        known = {o for action in parser._actions for o in action.option_strings}
        assert options <= known, f"{line!r}: {sorted(options - known)} not accepted by {command}"


def _parser(command: str, bench: str | None) -> argparse.ArgumentParser:
    """The argument parser a command builds (its ``--help``), captured without running the command."""
    import importlib
    from unittest import mock

    from course.__main__ import COMMANDS
    captured = {}
    real = argparse.ArgumentParser.parse_args

    class Captured(BaseException):                                      # no command catches it
        pass

    def grab(self, args=None, namespace=None):
        captured.setdefault("parser", self)
        raise Captured

    module = importlib.import_module(COMMANDS[command][0])
    with mock.patch.object(argparse.ArgumentParser, "parse_args", grab), \
            mock.patch.object(argparse.ArgumentParser, "parse_known_args",
                              lambda self, args=None, namespace=None: grab(self)):
        with pytest.raises(Captured):
            module.cli([bench] if bench else [])
    parser = captured["parser"]
    if bench:
        sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
        return sub.choices[bench]
    assert real                                                          # the real parse_args is untouched
    return parser


def test_the_readme_explains_every_commands_help_line():
    """Each command's one-line help in ``python -m course`` is short enough for the usage screen."""
    from course.__main__ import COMMANDS, usage
    text = usage()
    for name, (_, help_) in COMMANDS.items():
        assert f"  {name:<10} {help_}" in text and len(help_) < 100


def test_the_explorers_lectures_are_named():
    from course.viz import explorers  # noqa: F401  (registers the explorers)
    from course.viz import learning  # noqa: F401
    from course.viz.explorers import EXPLORERS
    lectures = sorted({key[:2] for key in EXPLORERS})
    text = README[README.index("Interactive explorers (ipywidgets)"):]
    text = text[:text.index("\n- **")]
    for number in lectures:
        assert f"({number})" in text, f"the README's explorer list does not name lecture {number}"
    for name in LECTURES:                                                # every lecture from 03 has an Explore
        if int(name[:2]) >= 3:
            import nbformat
            nb = nbformat.read(ROOT / "lectures" / name, as_version=4)
            heads = [c.source.splitlines()[0] for c in nb.cells if c.cell_type == "markdown" and c.source]
            assert any("Explore" in h for h in heads), f"{name} has no Explore section"


def test_the_start_here_commands_install_what_ci_installs():
    start = README[README.index("## Start here: two commands"):README.index("## What the course teaches")]
    commands = re.findall(r"```bash\n(python3 -m venv[^\n]+)\n```", start)
    assert len(commands) == 2
    open_course, run_tests = (shlex.split(c.replace("&&", " && ")) for c in commands)
    for words in (open_course, run_tests):
        assert "torch==2.13.0" in words                                  # the CPU build, first
        assert words.index("torch==2.13.0") < words.index("-e")
    assert commands[0].endswith("python -m course lab") and commands[1].endswith("pytest")
    ci = (ROOT / ".ci" / "run").read_text()
    assert "torch==2.13.0" in ci and '-e ".[test]"' in ci and "python -m pytest" in ci


def test_the_suites_timings_are_dated():
    start = README[README.index("**Run every test**"):README.index("`torch==2.13.0` is installed first")]
    for match in re.finditer(r"\d+ min \d+ s", start):
        before = start[:match.start()]
        assert re.search(r"20\d\d-\d\d-\d\d", before), f"{match.group()} has no date before it"

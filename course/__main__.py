"""Command line: ``python -m course lab | site | render | bench | grade | release | workspace | gradescope``.

Each sub-command lives beside the topic it belongs to and exposes ``cli(argv) -> int``.
"""
import importlib
import sys

COMMANDS = {
    "lab": ("course.lab", "JupyterLab at the course root: shipped notebooks read-only, the terminal finds the course"),
    "render": ("course.render_cli", "render a mesh (or the bundled default scene) to a PNG"),
    "bench": ("course.bench", "time against error, side by side"),
    "grade": ("course.grading.grader", "grade exercise notebooks: their code in a worker, the checks in the grader"),
    "release": ("course.grading.release", "write exercises/ from solutions/ (or --check for drift)"),
    "workspace": ("course.grading.workspace", "copy an exercise into work/, your own folder (never overwritten)"),
    "gradescope": ("course.grading.gradescope", "build the Gradescope autograder (a zip) of one exercise"),
    "site": ("course.site", "build the course's static website (lectures with their outputs, syllabus, README)"),
}


def usage() -> str:
    lines = ["usage: python -m course COMMAND [options]", "", "commands:"]
    lines += [f"  {name:<10} {help_}" for name, (_, help_) in COMMANDS.items()]
    lines += ["", "Run `python -m course COMMAND --help` for a command's options."]
    return "\n".join(lines)


def main(argv=None) -> int:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] in ("-h", "--help"):
        print(usage())
        return 0 if argv else 2
    name, rest = argv[0], argv[1:]
    if name not in COMMANDS:
        print(f"unknown command {name!r}\n\n{usage()}", file=sys.stderr)
        return 2
    module = importlib.import_module(COMMANDS[name][0])
    return int(module.cli(rest) or 0)


if __name__ == "__main__":
    sys.exit(main())

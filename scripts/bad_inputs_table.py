"""The README's troubleshooting table: what `asrbf` says about bad and odd inputs.

Runs the command-line matrix of ``tests/test_bad_inputs.py`` (``CLI_MATRIX``) in-process
through ``asrbf_mesh.cli.main`` with stderr captured, each row in a fresh copy of the
valid inputs in a temporary folder, and prints a Markdown table
``| input | command | exit code | message |`` with the temporary paths replaced by
``FILE`` (the file the message is about) and ``DIR`` (another path of the run).

By default a message shared by several commands for one input is shown once, with the
first command that prints it; ``--all`` prints every row. Rows that succeed without a
word (the controls) are left out. Run as root, the read-only-folder rows cannot be
exercised (root writes anyway); run as another user, or under ``unshare --user``.

Run from the repository root:  python scripts/bad_inputs_table.py [--all]
"""

from __future__ import annotations

import argparse
import importlib.util
import re
import shutil
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def _matrix_module():
    spec = importlib.util.spec_from_file_location(
        "test_bad_inputs", ROOT / "tests" / "test_bad_inputs.py")
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module  # dataclasses look their module up
    spec.loader.exec_module(module)
    return module


def _message(stderr: str, subject: Path, root: Path) -> str:
    text = " ".join(stderr.split())
    text = text.replace(str(subject), "FILE")
    text = re.sub(re.escape(str(root)) + r"[^\s:)\"]*", "DIR", text)
    return text.replace("|", "\\|")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--all", action="store_true", help="one row per command and input")
    args = ap.parse_args()
    m = _matrix_module()
    rows: list[tuple[str, str, str, str]] = []
    seen: set[tuple[str, str]] = set()
    with tempfile.TemporaryDirectory() as tmp:
        valid = m.build_valid(Path(tmp) / "valid")
        for i, case in enumerate(m.CLI_MATRIX):
            env = m.copy_env(valid, Path(tmp) / f"run{i}")
            subject = case.make(env)
            command = _command(case.argv(env, subject), subject, env.root)
            if case.case == "in a read-only folder" and m.writable_anyway(subject.parent):
                code, message = "-", "not run: this user (root) writes in read-only folders"
            else:
                res = m.run_case(case, env, subject)
                code, message = str(res.code), _message(res.stderr, subject, env.root)
            _unlock(env.root)
            shutil.rmtree(env.root)
            what = f"{case.kind}: {case.case}"
            if not message or (not args.all and (what, message) in seen):
                continue
            seen.add((what, message))
            rows.append((what, f"`{command}`", code, message))
    print("| input | command | exit code | message |")
    print("|---|---|---|---|")
    for row in rows:
        print("| " + " | ".join(row) + " |")
    return 0


_SPEED_OPTIONS = {"--passes", "--resolution", "--som-iterations", "--levels"}  # with a value
_SPEED_FLAGS = {"--no-meshes", "--no-metro"}


def _command(argv: list[str], subject: Path, root: Path) -> str:
    """The command line with ``FILE`` for the subject, other paths relative to the run."""
    words, skip = ["asrbf"], False
    for arg in argv:
        if skip or arg in _SPEED_FLAGS:
            skip = False
            continue
        if arg in _SPEED_OPTIONS:
            skip = True
            continue
        if arg == str(subject):
            arg = "FILE"
        elif arg.startswith(f"{root}/"):
            arg = arg[len(str(root)) + 1:]
        words.append(arg)
    return " ".join(words)


def _unlock(root: Path) -> None:
    locked = root / "locked"
    if locked.exists():
        locked.chmod(0o755)


if __name__ == "__main__":
    sys.exit(main())

"""The run-directory layout has one owner (gouge_cli.io.layout): its paths, and no path literal of a run
directory spelled anywhere else in gouge_cli, checked from the source. A path literal is a string
constant (an f-string's literal parts included) without white space; prose that names a file for
the reader (docstrings, help texts, error messages) is not one."""

from __future__ import annotations

import ast
import re
from pathlib import Path

from gouge_cli.io.layout import ForkLayout, RunLayout, branch_name, branch_perm

PACKAGE = Path(__file__).resolve().parents[2] / "gouge_cli"
OWNER = PACKAGE / "io" / "layout.py"
# a string constant (an f-string's literal parts included) that spells a run directory's file
FORBIDDEN = re.compile(r"run\.h5|latest\.h5|pair\.json|(^|/)checkpoints(/|$)|(^|/)forks(/|$)|forks/slip_|^perm_|"
                       r"^slip_\*|checkpoints/slip_")


def _docstrings(tree: ast.AST) -> set[int]:
    ids = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant):
                ids.add(id(first.value))
    return ids


def path_literals(path: Path) -> list[tuple[int, str]]:
    """(line, text) of the path literals of a run directory in one source file."""
    tree = ast.parse(path.read_text())
    skip = _docstrings(tree)
    return [(node.lineno, node.value) for node in ast.walk(tree)
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in skip
            and not re.search(r"\s", node.value) and FORBIDDEN.search(node.value)]


def test_no_run_directory_path_is_spelled_outside_the_layout():
    found = [f"{p.relative_to(PACKAGE.parent)}:{line}: {text!r}" for p in sorted(PACKAGE.rglob("*.py")) if p != OWNER
             for line, text in path_literals(p)]
    assert not found, "spell these through gouge_cli.io.layout:\n" + "\n".join(found)


def test_the_checker_sees_a_hand_built_path(tmp_path):
    src = tmp_path / "m.py"
    src.write_text('"""run.h5 in a docstring is fine."""\nx = run_dir / "forks" / f"slip_{n:03d}" / "run.h5"\n'
                   'raise OSError(f"{x}: no run.h5 in it")\n')
    assert sorted(text for _, text in path_literals(src)) == ["forks", "run.h5"]


def test_paths(tmp_path):
    run = RunLayout(tmp_path)
    assert run.run_file == tmp_path / "run.h5"
    assert run.latest == tmp_path / "checkpoints" / "latest.h5"
    assert run.slip_checkpoint(7) == tmp_path / "checkpoints" / "slip_007.h5"
    assert run.relative(run.slip_checkpoint(7)) == "checkpoints/slip_007.h5"
    fork = run.fork(3)
    assert fork.root == tmp_path / "forks" / "slip_003" and fork.slip == 3
    assert fork.pair_file == tmp_path / "forks" / "slip_003" / "pair.json"
    assert fork.branch(None).run_file == tmp_path / "forks" / "slip_003" / "drained" / "run.h5"
    assert fork.branch(1e-5).root.name == "perm_1e-05" == branch_name(1e-5)
    assert branch_perm(fork.branch(2.5e-5).root) == 2.5e-5


def test_branches_found(tmp_path):
    fork = ForkLayout(tmp_path / "forks" / "slip_001")
    for perm in (None, 1e-3, 1e-5):
        fork.branch(perm).root.mkdir(parents=True)
        fork.branch(perm).run_file.write_bytes(b"")
    drained, wet = fork.branches()
    assert drained == fork.branch(None).root
    assert [branch_perm(p) for p in wet] == [1e-5, 1e-3]
    assert RunLayout(tmp_path).fork_dirs() == [fork.root]
    assert len(RunLayout(tmp_path).branch_run_files()) == 3


def test_a_branch_is_known_by_its_place_in_the_layout(tmp_path):
    """RunLayout.fork_branch reads (parent run, slip, kappa_c) off RUN/forks/slip_NNN/<branch>,
    with or without a run file (an interrupted branch may have none yet)."""
    from gouge_cli.io.layout import RunLayout

    fork = RunLayout(tmp_path / "run").fork(7)
    assert fork.branch(None).fork_branch() == (tmp_path / "run", 7, None)
    assert fork.branch(3e-6).fork_branch() == (tmp_path / "run", 7, 3e-6)
    assert RunLayout(tmp_path / "run").fork_branch() is None
    assert RunLayout(tmp_path / "run" / "forks" / "slip_x" / "drained").fork_branch() is None
    assert RunLayout(fork.root / "notes").fork_branch() is None


def test_a_stopped_forks_command_names_the_folder_of_a_long_permeability(tmp_path):
    """The `gouge restart` line a stopped fork prints spells kappa_c as its branch folder does (perm_text):
    every digit of 3.333333333e-6, so that running the printed line continues that very branch."""
    import shlex

    from gouge_cli.io.rundir import restart_command
    from gouge_cli.workflows.fork import ForkRequest

    perm = 3.333333333e-6
    folder = RunLayout(tmp_path).fork(4).branch(perm).root.name
    assert folder == "perm_3.333333333e-06"
    for line in (restart_command(tmp_path, 4, [perm]), ForkRequest(tmp_path, 4, [perm]).command()):
        args = shlex.split(line)
        given = float(args[args.index("--perm") + 1])
        assert RunLayout(tmp_path).fork(4).branch(given).root.name == folder, line


def test_fork_folder_names_are_parsed_only_by_the_layout():
    """A fork folder's slip number is read by ForkLayout.slip, nowhere by hand (``name.split("_")``)."""
    found = [f"{p.relative_to(PACKAGE.parent)}:{i}" for p in sorted(PACKAGE.rglob("*.py")) if p != OWNER
             for i, line in enumerate(p.read_text().splitlines(), 1) if re.search(r"name\.split\([\"']_", line)]
    assert not found, "read the slip number with gouge_cli.io.layout.ForkLayout(...).slip:\n" + "\n".join(found)

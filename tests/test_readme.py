"""The README's command lines name commands, options and benchmark scripts that exist: users
copy them, so an option renamed in the code fails here rather than in their shell."""
from __future__ import annotations

import ast
import dataclasses
import functools
import re
import shlex
from pathlib import Path

import click
import pytest

from wirescene.cli.main import main as cli

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"


def _command_lines(text: str, program: str) -> list[str]:
    """Each ``program ...`` command of the README: the lines of its fenced shell blocks (a
    comment cut off, lines continued by a backslash joined) and its inline code spans."""
    commands, prose, fence = [], [], None
    for line in text.replace("\\\n", " ").splitlines():
        if line.lstrip().startswith("```"):  # a fence, also one indented under a list item
            fence = None if fence is not None else (line.lstrip()[3:].strip() or "text")
            continue
        if fence is None:
            prose.append(line)
        elif fence in ("bash", "sh", "console"):
            commands += _commands(line.split(" #")[0], program)
    for span in re.findall(r"`([^`]+)`", " ".join(prose)):
        commands += _commands(span, program)
    return commands


def _commands(text: str, program: str) -> list[str]:
    """The ``program ...`` commands of a shell line: chained ones each, without a console's ``$`` prompt or
    the environment variables set before them."""
    parts = [re.sub(r"^(\$\s+)?([A-Za-z_]\w*=\S*\s+)*", "", p.strip()) for p in re.split(r"&&|;|\|", text)]
    return [p for p in parts if p.startswith(program + " ")]


def _options(command: click.Command) -> set[str]:
    names = {"--help"}
    for param in command.params:
        names.update(getattr(param, "opts", []))
        names.update(getattr(param, "secondary_opts", []))
    return names


def _resolve(tokens: list[str]) -> tuple[click.Command, list[str]]:
    """The click command ``tokens`` name (``wirescene train detector ...``) and the path to it."""
    command, path = cli, ["wirescene"]
    for token in tokens[1:]:
        if not isinstance(command, click.Group) or token.startswith("-"):
            break
        sub = command.commands.get(token)
        if sub is None:
            break
        command, path = sub, [*path, token]
    return command, path


def _long_options(tokens: list[str]) -> list[str]:
    """The ``--name`` of every token that is one (``[--name VALUE]`` and ``--name=VALUE`` too): a token that
    starts with ``--`` and names no option, however it is spelled (``--min_score``), is one the check reports."""
    tokens = tokens[:tokens.index("--")] if "--" in tokens else tokens  # what follows goes to another command
    tokens = [t.strip("[]") for t in tokens]  # an optional part of a command line is still an option of it
    return [t.split("=")[0] for t in tokens if t.startswith("--") and len(t) > 2]


@functools.lru_cache(maxsize=None)
def _benchmark_options(script: Path) -> frozenset[str]:
    """The options the ``add_argument`` calls of ``script`` and of the benchmark modules it imports name (their
    parsers lend it options); a name merely quoted in the script (a command it runs) is none of its own."""
    names, todo, seen = {"--help"}, [script], set()
    while todo:
        path = todo.pop()
        seen.add(path)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "attr", None) == "add_argument":
                names.update(a.value for a in node.args if isinstance(a, ast.Constant) and isinstance(a.value, str))
            modules = ([a.name for a in node.names] if isinstance(node, ast.Import)
                       else [node.module] if isinstance(node, ast.ImportFrom) and node.module else [])
            todo += [m for m in (script.parent / f"{n}.py" for n in modules) if m.is_file() and m not in seen]
    return frozenset(names)


def _setting_problem(path: list[str], name: str) -> str | None:
    """Why ``--set NAME=...`` of command ``path`` names nothing (None: a setting it takes)."""
    from wirescene.fitting.options import STAGES, FitOptions
    from wirescene.training.pipeline import option_default

    stage, _, key = name.partition(".")
    if path[1:] == ["train", "all"]:
        try:
            option_default(stage, key)
        except ValueError as exc:
            return str(exc)
        return None
    if stage not in STAGES or key not in {f.name for f in dataclasses.fields(getattr(FitOptions(), stage))}:
        return f"no setting {name!r} (stages {', '.join(STAGES)})"
    return None


def _settings(tokens: list[str]) -> list[str]:
    """The names ``--set NAME=VALUE`` assigns in ``tokens``; placeholders (``STAGE.KEY``) left out."""
    values = [b for a, b in zip(tokens, tokens[1:]) if a == "--set"]
    values += [t.removeprefix("--set=") for t in tokens if t.startswith("--set=")]
    names = [v.partition("=")[0] for v in values]
    return [n for n in names if n != n.upper()]


def _split(command: str) -> list[str]:
    try:
        return shlex.split(command)
    except ValueError:  # an unbalanced quote in prose: whitespace is enough to find the options
        return command.split()


def test_readme_names_command_lines():
    # the extraction itself must find the README's commands, or the checks below pass on nothing
    text = README.read_text()
    assert len(_command_lines(text, "wirescene")) >= 40
    assert sum(".py" in line for line in _command_lines(text, "python")) >= 30


def _wirescene_problems(line: str, tokens: list[str]) -> list[str]:
    """What ``tokens`` (``wirescene ...``, of README line ``line``) name that does not exist."""
    command, path = _resolve(tokens)
    if isinstance(command, click.Group) and len(tokens) > len(path) and not tokens[len(path)].startswith("-"):
        return [f"{line!r}: {' '.join(path)} has no command {tokens[len(path)]!r}"]
    problems = []
    unknown = [o for o in _long_options(tokens) if o not in _options(command)]
    if unknown:
        problems.append(f"{line!r}: {' '.join(path)} has no option {', '.join(unknown)}")
    wrong = [p for p in (_setting_problem(path, n) for n in _settings(tokens)) if p]
    return problems + [f"{line!r}: --set {p}" for p in wrong]


def test_readme_wirescene_commands_exist_with_their_options():
    problems = []
    for line in _command_lines(README.read_text(), "wirescene"):
        problems += _wirescene_problems(line, _split(line))
    assert not problems, "\n".join(problems)


# the benchmarks that pass what follows `--` on to a command of ours, which must take it
PASSED_ON = {"bench_eval_scale.py": ["wirescene", "eval", "ROOT"]}


def test_readme_benchmark_commands_name_scripts_and_options_that_exist():
    problems = []
    lines = _command_lines(README.read_text(), "python")
    for line in lines:
        tokens = _split(line)
        scripts = [t for t in tokens[1:3] if t.endswith(".py")]
        if not scripts:
            continue
        script = ROOT / scripts[0]
        if not script.is_file():
            problems.append(f"{line!r}: no script {scripts[0]}")
            continue
        unknown = [o for o in _long_options(tokens) if o not in _benchmark_options(script)]
        if unknown:
            problems.append(f"{line!r}: {scripts[0]} has no option {', '.join(unknown)}")
        # a benchmark's --set is the fit's (bench_real_folds.py, bench_other_cameras.py)
        wrong = [p for p in (_setting_problem(["wirescene"], n) for n in _settings(tokens)) if p]
        problems += [f"{line!r}: --set {p}" for p in wrong]
        if "--" in tokens and script.name in PASSED_ON:
            problems += _wirescene_problems(line, PASSED_ON[script.name] + tokens[tokens.index("--") + 1:])
    assert not problems, "\n".join(problems)


def test_readme_settings_told_alone_exist():
    # `--set NAME=VALUE` in prose, of the fit's stages or of `train all`'s steps
    names = [n for span in _command_lines(README.read_text(), "--set") for n in _settings(_split(span))]
    assert len(names) >= 8
    wrong = [n for n in names
             if _setting_problem(["wirescene"], n) and _setting_problem(["wirescene", "train", "all"], n)]
    assert not wrong, f"README's --set names nothing: {wrong}"


@pytest.mark.parametrize("line, problem", [
    ("wirescene eval ROOT --no-such-option 3", "wirescene eval has no option --no-such-option"),
    ("wirescene train nonsense --out M", "wirescene train has no command 'nonsense'"),
    ("wirescene evaluate ROOT", "wirescene has no command 'evaluate'"),
    ("python benchmarks/bench_real_folds.py --root R --no-such-option", "bench_real_folds.py has no option --no-such"),
    ("python benchmarks/bench_nothing.py --root R", "no script benchmarks/bench_nothing.py"),
    ("wirescene predict R --out O --set lifting.camera_hight=1.3", "--set no setting 'lifting.camera_hight'"),
    ("wirescene train all R --out M --set parts.n_tree=3", "--set step parts has no option 'n_tree'"),
    ("wirescene predict R --out O [--resum]", "wirescene predict has no option --resum"),
    ("wirescene fit I --calib C [--detection D.json] --out O", "wirescene fit has no option --detection"),
    ("wirescene pitch R --camera_height 1.3", "wirescene pitch has no option --camera_height"),
    ("wirescene eval R --jsn=m.json", "wirescene eval has no option --jsn"),
    ("OMP_NUM_THREADS=1 wirescene eval R --jsn m.json", "wirescene eval has no option --jsn"),
    ("wirescene demo --out D && wirescene eval R --jsn m.json", "wirescene eval has no option --jsn"),
    ("python benchmarks/bench_fit.py --frame 000010 --no-such-option", "bench_fit.py has no option --no-such-option"),
    ("python benchmarks/bench_eval_scale.py W --root R --detections bank", "bench_eval_scale.py has no option --det"),
    ("python benchmarks/bench_real_folds.py --root R --set lifting.camera_hight=1", "--set no setting 'lifting.came"),
    ("python benchmarks/bench_eval_scale.py W --root R -- --variant full --detection bank",
     "wirescene eval has no option --detection"),
])
@pytest.mark.parametrize("where", ["span", "fence", "indented fence", "continued"])
def test_readme_check_finds_a_wrong_command(line, problem, where, monkeypatch, tmp_path):
    fine = "wirescene demo --out D  # a comment --not-an-option\npython benchmarks/bench_fit.py --frame 000010"
    head, _, tail = line.rpartition(" ")
    text = {"span": f"Run `{line}` now.\n\n```bash\n{fine}\n```\n",
            "fence": f"Run:\n\n```bash\n{fine}\n{line}\n```\n",
            "indented fence": f"- Run:\n\n  ```bash\n  {line}\n  ```\n\n`wirescene demo --out D`\n",
            "continued": f"```bash\n{fine}\n{head} \\\n    {tail}\n```\n"}[where]
    readme = tmp_path / "README.md"
    readme.write_text(text)
    monkeypatch.setattr(f"{__name__}.README", readme)
    with pytest.raises(AssertionError, match=re.escape(problem)):
        test_readme_wirescene_commands_exist_with_their_options()
        test_readme_benchmark_commands_name_scripts_and_options_that_exist()


@pytest.mark.parametrize("variant", ["coarse", "full"])
def test_readme_names_every_key_of_a_fitted_images_json(variant):
    # the README's account of `fit`'s and `predict --json-dir`'s JSON names every key a fit writes
    import json

    import wirescene
    from conftest import KITTI_ROOT
    from wirescene.io.outputs import scene_json

    text = README.read_text()
    start = text.index("The JSON of a fitted image")
    named = set(re.findall(r"`([a-z_0-9]+)`", " ".join(text[start:text.index("\n\n", start)].split())))
    split = KITTI_ROOT / "training"
    scene = wirescene.fit(split / "image_2" / "000010.png", split / "calib" / "000010.txt",
                          boxes=[[354, 185, 549, 294]], variant=variant, particles=8,
                          settings={"inference.iterations": 1, "inference.polish_iterations": 0})
    written = json.loads(scene_json("000010", scene, scene.detections))
    keys = set(written) | set(written["objects"][0]) | set(written["objects"][0]["ground_plane"])
    assert ("vertices" in keys) == (variant == "full")
    assert keys <= named, f"README's JSON paragraph names none of {sorted(keys - named)}"

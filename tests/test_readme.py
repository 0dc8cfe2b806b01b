"""The README is for users: its example specification, its commands and its links must stay true.

Nothing here runs a simulation: the example is resolved as a specification, the commands' options
are checked against the commands' own, and links against the files of the repository."""

import re
import sys
from pathlib import Path

import pytest

from decco_warp import spec as specs

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - Python 3.10
    import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
README = (ROOT / "README.md").read_text(encoding="utf-8")
KEY = re.compile(r"^(#\s*)?([A-Za-z_]+)\s*=\s*(.*?)\s*(#.*)?$")


def _blocks(text: str, language: str) -> list[str]:
    return re.findall(rf"^```{language}\n(.*?)^```$", text, flags=re.S | re.M)


def _example() -> str:
    """The TOML of the README's "Your own collision"."""
    section = README.split("## Your own collision", 1)[1].split("\n## ", 1)[0]
    (block,) = _blocks(section, "toml")
    return block


def _example_keys() -> dict[str, dict[str, tuple[str, bool, str]]]:
    """{table: {key: (value text, commented out, its comment with the comment lines that follow)}}."""
    keys: dict[str, dict] = {}
    table, last = None, None
    for line in _example().splitlines():
        if re.fullmatch(r"\[(\w+)\]", line.strip()):
            table, last = line.strip()[1:-1], None
            keys[table] = {}
            continue
        if table is None:
            continue
        if line.startswith(" ") and line.strip().startswith("#") and last is not None:  # a comment's next line
            value, commented, comment = keys[table][last]
            keys[table][last] = (value, commented, comment + " " + line.strip().lstrip("# "))
            continue
        match = KEY.match(line)
        if match:
            last = match.group(2)
            keys[table][last] = (match.group(3), bool(match.group(1)), match.group(4) or "")
    return keys


def test_the_example_names_every_key_of_every_table():
    keys = _example_keys()
    assert list(keys) == list(specs.SCHEMA)
    for table, schema in specs.SCHEMA.items():
        assert set(keys[table]) == set(schema), f"[{table}]: missing {set(schema) - set(keys[table])}, unknown {set(keys[table]) - set(schema)}"
        for key, (_, _, comment) in keys[table].items():
            assert comment.strip("# "), f"[{table}] {key} has no comment giving its unit and allowed values"


def test_the_example_resolves_and_each_value_shown_is_the_default_unless_it_says_so():
    raw = tomllib.loads(_example())
    spec = specs.resolve_spec(raw)
    assert spec["run"]["steps"] == 100_000 and spec["collision"]["eta"] == 1.0
    for table, keys in _example_keys().items():
        for key, (value, commented, comment) in keys.items():
            default = specs.SCHEMA[table][key].default
            if commented or default is None:
                continue
            shown = tomllib.loads(f"v = {value}")["v"]
            if shown != default:
                assert "default" in comment, f"[{table}] {key} = {value} is not the default ({default!r}) and does not say so"


@pytest.mark.parametrize("table, key", [(t, k) for t, keys in _example_keys().items() for k, v in keys.items() if v[1]])
def test_each_key_commented_out_in_the_example_is_valid_when_given(table, key):
    raw = tomllib.loads(_example())
    value = tomllib.loads(f"v = {_example_keys()[table][key][0]}")["v"]
    raw[table][key] = value
    for either, other in (("steps", "duration"), ("speed", "eta")):
        if key == either:
            raw[table].pop(other)
    resolved = specs.resolve_spec(raw)
    assert resolved[table][key] == value


def _commands() -> list[list[str]]:
    """Every `decco-warp ...` command of the README's and docs' bash blocks and inline code, as words."""
    commands = []
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        text = path.read_text(encoding="utf-8")
        lines = []
        for block in _blocks(text, "bash"):
            lines += block.replace("\\\n", " ").splitlines()
        lines += re.findall(r"`(decco-warp [^`]+)`", text)
        for line in lines:
            line = line.split("#", 1)[0].strip()
            if line.startswith("decco-warp "):
                commands.append(line.split())
    return commands


def test_every_option_of_the_documented_commands_exists():
    import typer

    from decco_warp.cli import app

    group = typer.main.get_command(app)
    commands = _commands()
    assert any(words[1] == "simulate" for words in commands) and any(words[1] == "analyze" for words in commands)
    for words in commands:
        name = words[1]
        if name.startswith("-") or name in ("COMMAND", "...") or name == "--help":
            continue
        assert name in group.commands, f"{' '.join(words)}: no command {name}"
        options = {opt for param in group.commands[name].params for opt in (*param.opts, *param.secondary_opts)}
        for word in words[2:]:
            if word.startswith("-") and word not in ("...",):
                assert word.split("=", 1)[0] in options | {"--help"}, f"{' '.join(words)}: decco-warp {name} has no {word}"


def test_the_readme_gives_the_commands_that_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    assert 'pip install -e ".[test]"' in ci and "pytest" in ci
    assert 'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && pytest' in README
    assert "python3 -m venv .venv && . .venv/bin/activate && pip install -e . && decco-warp simulate" in README


def test_every_relative_link_of_the_readme_and_the_docs_exists():
    for path in [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]:
        for target in re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", path.read_text(encoding="utf-8")):
            if "://" in target:
                continue
            assert (path.parent / target).exists(), f"{path.relative_to(ROOT)} links to {target}, which does not exist"

"""The README's command summary is the parsers' own usage, and every command the README shows
parses (an option missing from the summary, shown as required when it is optional, or
misspelt in an example fails here)."""

from __future__ import annotations

import argparse
import re
import shlex

import pytest

from support.command_summary import README, command_summary, readme_block


def test_the_command_summary_is_the_parsers_usage() -> None:
    _, _, lines = readme_block(README.read_text(encoding="utf-8"))
    expected = command_summary()
    missing = [line for line in expected if line not in lines]
    stale = [line for line in lines if line not in expected]
    assert not missing and not stale, (
        "README command summary differs from the parsers; run `python tests/support/command_summary.py --write`\n"
        + "\n".join([f"missing: {m}" for m in missing] + [f"stale:   {s}" for s in stale]))


def test_the_summary_shows_optional_options_in_brackets() -> None:
    """An independent check of the generator on the cases the README once got wrong."""
    lines = {" ".join(line.split()[:3 if line.startswith(("acoustisim dataset", "acoustisim scene",
                                                             "acoustisim experiment")) else 2]): line
             for line in command_summary()}
    assert "[--method METHOD]" in lines["binsonar detect"]  # optional: the default method runs
    for option in ("[--echo N|NAME]", "[--no-paths]", "[--camera {top,side,sonar,perspective,targets}]"):
        assert option in lines["acoustisim view"]
    assert "--out DATA.zarr" in lines["acoustisim dataset generate"]  # required: no brackets
    assert "[--out DATA.zarr]" not in lines["acoustisim dataset generate"]
    assert "[--toml]" not in lines["acoustisim scene show"] and "[--json | --toml]" in lines["acoustisim scene show"]


def _readme_commands() -> list[str]:
    """Every ``acoustisim ...`` or ``binsonar ...`` command in the README's bash blocks."""
    text = README.read_text(encoding="utf-8")
    commands = []
    for block in re.findall(r"```bash\n(.*?)```", text, flags=re.S):
        for line in block.splitlines():
            line = line.split("#", 1)[0]
            for part in re.split(r"&&|\|", line):
                part = part.split(">", 1)[0].strip()
                if part.startswith(("acoustisim ", "binsonar ")):
                    commands.append(part)
    return commands


@pytest.mark.parametrize("command", _readme_commands())
def test_every_command_in_the_readme_parses(command: str) -> None:
    from acoustisim.cli.main import build_parser as acoustisim_parser
    from binsonar.cli.main import build_parser as binsonar_parser

    words = shlex.split(command)
    parser = acoustisim_parser() if words[0] == "acoustisim" else binsonar_parser()
    try:
        args = parser.parse_args(words[1:])
    except SystemExit as exc:  # argparse's usage error
        raise AssertionError(f"README command does not parse: {command}") from exc
    assert isinstance(args, argparse.Namespace) and callable(getattr(args, "run", None))


def test_the_readme_shows_commands() -> None:
    assert len(_readme_commands()) >= 10

"""``latentrl <command> --help``: every command ends with an example line and shows its options' defaults."""

import argparse

import pytest

from latentrl.app.cli import EXAMPLES, build_parser, main, subcommands

COMMANDS = [words for words, _ in subcommands(build_parser())]


def test_every_command_has_an_example_and_no_example_names_a_missing_command():
    names = {" ".join(words) for words in COMMANDS}
    assert names == set(EXAMPLES), (names ^ set(EXAMPLES))
    for name, line in EXAMPLES.items():
        assert line.startswith("latentrl "), name


@pytest.mark.parametrize("words", COMMANDS, ids=[" ".join(w) for w in COMMANDS])
def test_help_shows_the_example_and_every_default(words, capsys):
    assert main([*words, "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())  # argparse wraps lines: compare with single spaces
    assert f"example: {EXAMPLES[' '.join(words)]}" in text
    parser = dict(subcommands(build_parser()))[words]
    for action in parser._actions:
        if not action.option_strings or any(action.default is v for v in (None, False, True, argparse.SUPPRESS)):
            continue
        default = action.default
        shown = " ".join(map(str, default)) if isinstance(default, list) else str(default)
        help_text = " ".join((action.help or "").split())
        assert f"(default: {shown})" in text or "(default" in help_text, (action.option_strings, shown)


def test_a_default_written_by_the_formatter_matches_the_parsed_value(capsys):
    assert main(["motion", "sample", "--help"]) == 0
    text = " ".join(capsys.readouterr().out.split())
    assert "classifier-free guidance scale (default: 5.0)" in text and "(default: motion.npz)" in text


@pytest.mark.parametrize("name", sorted(EXAMPLES))
def test_every_example_parses(name):
    import shlex

    words = shlex.split(EXAMPLES[name])
    args = build_parser().parse_args(words[1:])  # argparse exits on a flag the command does not have
    assert callable(args.func)

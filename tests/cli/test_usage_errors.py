"""Usage errors (click's: a missing argument, an unknown option, an option without its value, a value of
the wrong type or out of its range) are reported like every other error: one ``ffd: error:`` line on
stderr naming what was wrong and where the usage is, exit 2, and with ``--json`` the JSON object of a
failure on stdout. Generated for every command from its own parameters."""

from __future__ import annotations

import json

import click
import pytest
from hostile import ffd_inproc

from ffdcli.cli import _register, cli

_register()
COMMANDS = dict(cli.commands)


def _bad_value(param: click.Parameter) -> str | None:
    """A value that the parameter's type refuses (None when it takes any text)."""
    t = param.type
    if isinstance(t, click.Choice):
        return "not-a-choice"
    if isinstance(t, click.IntRange) and t.min is not None:
        return str(int(t.min) - 1)
    if isinstance(t, click.FloatRange) and t.min is not None:
        return str(float(t.min) - 1.0)
    if isinstance(t, (click.types.IntParamType, click.types.FloatParamType)):
        return "twelve"
    if getattr(param, "callback", None) is not None and param.name in ("points", "degree"):
        return "six,eight"
    return None


def _positional(cmd: click.Command) -> list[str]:
    """Placeholder values of the command's required arguments (nothing is read: the usage error comes first)."""
    return [f"{p.name}.yaml" for p in cmd.params if isinstance(p, click.Argument) and p.required]


def _cases():
    for name, cmd in COMMANDS.items():
        args = _positional(cmd)
        required = [p for p in cmd.params if isinstance(p, click.Option) and p.required]
        req_args = [x for p in required for x in (p.opts[0], "x.csv")]
        if args:
            yield name, "missing argument", [name, *req_args]
        yield name, "unknown option", [name, *args, *req_args, "--no-such-option"]
        yield name, "extra argument", [name, *args, *req_args, "surplus1", "surplus2"] if name != "optimize" \
            else [name, *args, *req_args, "c0.twist"]
        for p in required:
            yield name, f"missing {p.opts[0]}", [name, *args, *[x for q in required if q is not p
                                                                 for x in (q.opts[0], "x.csv")]]
        for p in cmd.params:
            if not isinstance(p, click.Option) or p.is_flag or p.count:
                continue
            yield name, f"{p.opts[0]} without its value", [name, *args, *req_args, p.opts[0]]
            bad = _bad_value(p)
            if bad is not None:
                yield name, f"{p.opts[0]} {bad}", [name, *args, *req_args, p.opts[0], bad]
    yield "ffd", "no such command", ["no-such-command"]
    yield "ffd", "unknown global option", ["--no-such-option"]


CASES = list(_cases())


def test_the_cases_cover_every_command():
    assert {c[0] for c in CASES} >= set(COMMANDS)
    assert len(CASES) > 60


@pytest.mark.parametrize("as_json", [False, True], ids=["text", "json"])
@pytest.mark.parametrize("command, what, argv", CASES, ids=[f"{c}-{w}" for c, w, _ in CASES])
def test_usage_error_is_one_line_exit_2(tmp_path, command, what, argv, as_json):
    args = [*argv, "--json"] if as_json and "without its value" not in what else list(argv)
    if as_json and "without its value" in what:
        args = [argv[0], "--json", *argv[1:]]
    proc = ffd_inproc(*args, cwd=tmp_path)
    assert proc.returncode == 2, (args, proc.returncode, proc.stdout, proc.stderr)
    lines = proc.stderr.splitlines()
    assert len(lines) == 1 and lines[0].startswith("ffd: error: "), (args, proc.stderr)
    assert "Usage:" not in proc.stderr and "Traceback" not in proc.stderr
    assert "--help` shows the usage" in lines[0]
    if command != "ffd":
        assert f"`ffd {command} --help`" in lines[0], lines[0]
    if as_json:
        obj = json.loads(proc.stdout)
        assert obj["ok"] is False and obj["exit_code"] == 2 and obj["error"] == lines[0][len("ffd: error: "):]
    else:
        assert proc.stdout == ""
    assert list(tmp_path.iterdir()) == []          # nothing written


def test_help_and_version_still_print_and_exit_0(tmp_path):
    for args in (["--help"], ["deform", "--help"], ["--version"], ["box", "-h", "--json"]):
        proc = ffd_inproc(*args, cwd=tmp_path)
        assert proc.returncode == 0 and proc.stdout and not proc.stderr, args

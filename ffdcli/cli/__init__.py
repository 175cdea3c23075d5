"""The ``ffd`` command line: a thin layer over the library.

Each command lives in its own module of this package and imports the library lazily, so that
``ffd --help`` stays fast. Errors: :class:`ffdcli.errors.FfdError` subclasses become a one-line
message and their exit code (2 bad input, 3 quality check); anything else is reported in one
line with exit code 1 (``-v`` shows the traceback).
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
import traceback
import warnings

import click

from ffdcli import __version__
from ffdcli.cli.console import Console, StdoutError
from ffdcli.errors import FfdError, SignalRecorder, Terminated, interrupt_message, outputs_ledger
from ffdcli.io.jsontext import to_json

CONTEXT = {"help_option_names": ["-h", "--help"], "max_content_width": 100}


def common_options(func):
    """Adds -q/--quiet, -v/--verbose and --json to a command and passes ``console``."""

    @click.option("-q", "--quiet", is_flag=True, help="Print nothing but errors.")
    @click.option("-v", "--verbose", is_flag=True, help="Print more detail (and tracebacks of bugs).")
    @click.option("--json", "as_json", is_flag=True,
                  help="Print one JSON object as the summary instead of text (for scripts).")
    @functools.wraps(func)
    def wrapper(*args, quiet, verbose, as_json, **kwargs):
        obj = click.get_current_context().find_root().obj or {}
        console = Console(quiet=quiet, verbose=verbose, json=as_json, comm=obj.get("comm"))
        click.get_current_context().meta["ffd.console"] = console
        return func(*args, console=console, **kwargs)

    return wrapper


class _Group(click.Group):
    """Lists commands in the order they were added (the order a user meets them)."""

    def list_commands(self, ctx):
        return list(self.commands)


@click.group(cls=_Group, context_settings=CONTEXT)
@click.version_option(__version__, "-V", "--version", prog_name="ffd")
def cli():
    """Automatic free-form deformation (FFD) of wing meshes for aerodynamic design.

    \b
    Typical use:
      ffd inspect wing.su2              what is in the mesh: markers, bounds, axes
      ffd init wing.su2 -o wing.yaml    a commented starter design file (uncomment a change)
      ffd box wing.su2 --points 6,8,2   fit a lattice to the wing and embed it (cached)
      ffd deform design.yaml            apply twist/span/sweep/dihedral/chord/shape, write the mesh
      ffd plot design.yaml -o wing.png  original (black) and deformed (red) wing with its lattice
      ffd fit airfoil.yaml --target s1223.dat         2D: shape values that morph into a target
      ffd grad design.yaml --sens surface_sens.csv    dJ/d(design variables) for an optimiser
      ffd constraints design.yaml --json              thickness/volume/fold constraints, exact Jacobian

    Every command has --help, -q/--quiet, -v/--verbose and --json. Exit status: 0 success,
    2 bad input, 3 the deformed mesh failed the quality check (nothing written), 1 other errors.
    """


def _register():
    from ffdcli.cli import commands  # noqa: F401  (each module adds its command to ``cli``)


def _compiled_code_guards(argv: list[str], notice: bool):
    """Ctrl-C held while numba loads or compiles kernels (an interrupt there crashes the interpreter
    later), a kernel that numba cannot save in its cache used all the same (a warning with ``notice``)
    and, when ``notice``, a line on stderr before the first compile of a kernel
    (:mod:`ffdcli.jit`). Nothing for ``--help``/``--version``, which run no kernel: importing numba
    would double the time of ``ffd --help``."""
    if not argv or any(a in ("-h", "--help", "-V", "--version") for a in argv):
        return contextlib.nullcontext()
    from ffdcli.jit import cache_failures_warn, compile_notice, interrupts_outside_compilers

    stack = contextlib.ExitStack()
    stack.enter_context(interrupts_outside_compilers())
    # a kernel numba cannot save (a full disk, a file-size limit) is a warning, not a failed run
    stack.enter_context(cache_failures_warn(None if notice else (lambda text: None)))
    if notice:
        stack.enter_context(compile_notice())
    return stack


def main(argv=None):
    """Entry point of the ``ffd`` console script.

    Under ``mpiexec -n N`` (N > 1, the ``[mpi]`` extra) the command runs on every rank with one
    communicator (:func:`ffdcli.parallel.comm.world`); at the end the ranks agree on the outcome, so they
    all exit with the same status and only rank 0 prints the error."""
    _register()
    argv = list(sys.argv[1:] if argv is None else argv)
    as_json = "--json" in argv
    verbose = "-v" in argv or "--verbose" in argv
    # under mpiexec, SIGTERM/SIGHUP are held from before MPI starts (``ffd``'s entry point holds
    # them from before the imports): every rank stops together
    with SignalRecorder() as signals, outputs_ledger(), warnings.catch_warnings():
        warnings.showwarning = functools.partial(_show_warning, verbose=verbose)
        _run(argv, as_json, verbose, signals)


def _show_warning(message, category, filename, lineno, file=None, line=None, *, verbose: bool = False):
    """A Python warning that reaches the command line (a library's, e.g. NumPy's "invalid value
    encountered"): one ``ffd: warning:`` line instead of the warning and its source line; where it
    was raised with ``-v``."""
    where = f" ({filename}:{lineno})" if verbose else ""
    with contextlib.suppress(OSError, ValueError):
        print(f"ffd: warning: {category.__name__}: {' '.join(str(message).split())}{where}", file=sys.stderr,
              flush=True)


def _run(argv, as_json, verbose, signals):
    """The command, its errors agreed on over the MPI ranks and reported once; exits."""
    from ffdcli.parallel.comm import SerialComm, world

    try:
        comm = world()
    except FfdError as e:
        comm = SerialComm()
        _fail(str(e), e.exit_code, as_json)
    if comm.size > 1:
        comm.signals = signals
    try:
        try:
            quiet = "-q" in argv or "--quiet" in argv
            with _compiled_code_guards(argv, comm.is_root and not quiet):
                cli.main(args=argv, prog_name="ffd", standalone_mode=False, obj={"comm": comm})
            error = None
        except BaseException as e:   # noqa: BLE001 - agreed on below, then reported as before
            error = e
        if comm.size > 1 and not getattr(error, "ffd_agreed", False):
            comm.agree(error, signals=False)   # the last agreement: every rank learns how every other ended
        if error is not None:
            raise error
    except click.exceptions.Exit as e:
        sys.exit(e.exit_code)
    except click.exceptions.NoArgsIsHelpError as e:      # a bare ``ffd`` (or group): its help, exit 2
        if comm.is_root:
            e.show()
        sys.exit(e.exit_code)
    except click.ClickException as e:        # usage errors: one line, exit 2 (click's own convention)
        _fail(usage_message(e, argv), e.exit_code, as_json, show=comm.is_root)
    except (click.Abort, KeyboardInterrupt):
        _fail(interrupt_message(KeyboardInterrupt()), 130, as_json)
    except Terminated as e:           # SIGTERM / SIGHUP during a write: the temporary files are gone
        _fail(interrupt_message(e), 128 + e.signum, as_json, show=comm.is_root)
    except StdoutError as e:          # stdout full or closed: the outputs are complete; say it on stderr
        _quiet_stdout()
        _fail(str(e), 1, False)
    except FfdError as e:
        _fail(str(e), e.exit_code, as_json, extra=getattr(e, "report", None), show=comm.is_root)
    except BrokenPipeError:           # e.g. ffd ... --json | head -c 10
        _quiet_stdout()
        sys.exit(1)
    except MemoryError:
        _fail("out of memory", 1, as_json, show=comm.is_root)
    except Exception as e:  # a bug: one line unless -v
        if verbose:
            traceback.print_exc()
        _fail(f"internal error: {type(e).__name__}: {e} (this is a bug in ffd; -v shows where)",
              1, as_json, show=comm.is_root)
    sys.exit(0)


def usage_message(e: click.ClickException, argv: list[str] = ()) -> str:
    """Click's error (a usage error: a missing argument, an unknown option, a value of the wrong type) as
    the one line of every other error, with where the usage is: ``Missing argument 'DESIGN.yaml'.`` ->
    ``missing argument 'DESIGN.yaml'; `ffd deform --help` shows the usage``."""
    text = " ".join(e.format_message().split()).rstrip(".")
    text = text[:1].lower() + text[1:] if text[:2] != text[:2].upper() else text
    ctx = getattr(e, "ctx", None)
    where = ctx.command_path if ctx is not None else "ffd"
    if where == "ffd":              # an option's error is raised before its command's context exists
        where = next((f"ffd {a}" for a in argv if a in cli.commands), where)
    return f"{text}; `{where} --help` shows the usage"


def _fail(message: str, code: int, as_json: bool, extra: dict | None = None, show: bool = True):
    if not show:             # another MPI rank than 0: rank 0 reports the (agreed) error
        sys.exit(code)
    with contextlib.suppress(OSError):
        click.echo(f"ffd: error: {message}", err=True)
    if as_json:
        obj = {"ok": False, "exit_code": code, "error": message}
        if extra:
            obj["report"] = extra
        try:
            click.echo(to_json(obj))
            sys.stdout.flush()
        except OSError:
            _quiet_stdout()
    sys.exit(code)


def _quiet_stdout() -> None:
    """Point stdout at /dev/null so that the interpreter's last flush cannot fail a second time."""
    with contextlib.suppress(OSError, ValueError, AttributeError):
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())

"""`python -m ffdcli` is the same as the `ffd` command (whose entry point is :func:`run`)."""

import sys


def run() -> None:
    """Load the command line and run it. Ctrl-C while the modules load (numpy, numba: about a second)
    ends like one during the work: one line, status 130, no traceback."""
    from ffdcli.errors import SignalRecorder  # noqa: PLC0415  (light, stdlib only)

    # under mpiexec, SIGTERM/SIGHUP recorded from here (before numpy loads) to the end of the run, then
    # ignored: a signal during the interpreter's exit (MPI_Finalize) changes nothing of a finished run
    recorder = SignalRecorder()
    recorder.__enter__()
    try:
        from ffdcli.cli import main  # noqa: PLC0415  (imported here: an interrupt during the import is caught)

        main()                       # its first imports (the commands, numpy) are before its own handling
    except KeyboardInterrupt:
        sys.stderr.write("ffd: error: interrupted; nothing was written\n")
        sys.exit(130)
    finally:
        recorder.ignore_from_now_on()


if __name__ == "__main__":
    run()

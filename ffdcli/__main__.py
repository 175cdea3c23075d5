"""`python -m ffdcli` is the same as the `ffd` command."""

from ffdcli.cli import main

if __name__ == "__main__":
    main()

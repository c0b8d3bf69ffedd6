"""`python -m ilfo`: the `ilfo` command."""

from ilfo.cli import main

if __name__ == "__main__":
    raise SystemExit(main())

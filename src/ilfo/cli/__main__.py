"""``python -m ilfo.cli``."""

from ilfo.cli import main

raise SystemExit(main())

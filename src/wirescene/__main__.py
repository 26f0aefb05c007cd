"""``python -m wirescene``: the ``wirescene`` command, for an environment without its console script."""

from wirescene.cli.main import console_main

if __name__ == "__main__":  # pragma: no cover
    console_main()

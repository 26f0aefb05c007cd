"""The ``wirescene`` console script's entry point, :func:`console_main`.

It lives outside the package because importing anything of ``wirescene`` imports the
package root, and with it the API, every layer under it and numpy (about half a second):
a Ctrl-C then, before the command installs its handling of stop signals, ended the
process with a traceback and exit code 1. This module imports only the standard library's
``signal`` and ``sys``, so that the script's import of it is over at once, and imports the
command inside :func:`console_main`, where a Ctrl-C during the imports ends as one at any
later time does: the line ``wirescene: interrupted`` and exit code 130.
"""

from __future__ import annotations

import signal
import sys


def console_main() -> None:
    """Run ``wirescene`` on this process's command line
    (:func:`wirescene.cli.main.console_main`), a Ctrl-C while the command is imported
    included: it ends with ``wirescene: interrupted`` on standard error and exit code 130
    (128 + SIGINT), without a traceback, and a second Ctrl-C cuts nothing short. (SIGTERM and
    SIGHUP during the imports end the process by their default action: nothing is written
    yet.)"""
    try:
        from wirescene.cli.main import console_main as run

        run()
    except KeyboardInterrupt:  # Python's own SIGINT handler, before the command sets its handling
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        sys.stderr.write("wirescene: interrupted\n")
        sys.stderr.flush()
        sys.exit(128 + signal.SIGINT)


if __name__ == "__main__":  # pragma: no cover
    console_main()

"""How a stress run is stopped: `Stopped`, raised in the main process
by the first SIGINT or SIGTERM (drake_wbc.stress.run.stopped_by_signals),
and `stop_within`, which finds it behind the exceptions it caused. A
case (drake_wbc.stress.cases.run_case) records its own exceptions but
lets a stop through.
"""

import signal


class Stopped(BaseException):
    """A stress run stopped by a signal (SIGINT or SIGTERM); `code` is the
    exit code, 128 + the signal's number. A BaseException, as
    KeyboardInterrupt, so that no `except Exception` swallows it."""

    def __init__(self, signum):
        super().__init__(signal.Signals(signum).name)
        self.signum, self.code = signum, 128 + signum


def stop_within(error):
    """The Stopped that `error` is or was raised from, or None. A signal's
    Stopped raised while Python code runs on behalf of compiled code (a
    compiled kernel's call back into the interpreter) comes out of it as
    a SystemError caused by the Stopped."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, Stopped):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None

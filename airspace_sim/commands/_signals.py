"""SIGTERM handled like Ctrl-C by the long-running commands (``run``, ``replay``): the
loop stops between steps, what it writes is written, the exit status is 128 + 15."""


class Terminated(KeyboardInterrupt):
    """SIGTERM during a run: handled like Ctrl-C (the checkpoint is saved), exit 128 + 15."""

    exit_status = 128 + 15


class SigtermFlag:
    """While active, SIGTERM only sets :attr:`received`; the run loop checks it between
    steps. (Raising from the handler could land inside a library's ``__del__``, where the
    exception is ignored and the signal lost.)"""

    def __init__(self):
        self.received = False
        self._previous = None

    def __enter__(self):
        import signal
        import threading

        if threading.current_thread() is threading.main_thread():
            self._previous = signal.signal(signal.SIGTERM, self._handle)
        return self

    def _handle(self, signum, frame):
        self.received = True

    def __exit__(self, *exc):
        import signal

        if self._previous is not None:
            signal.signal(signal.SIGTERM, self._previous)

"""A stop request that comes while a streaming run is already ending:
noted, not obeyed, so that the run's end is written whole.

`compensate`'s loop ends its run on SIGTERM (a service manager's stop) or
Ctrl-C as on any other end: the event logged, the sockets closed, the log's
last rows, summary.json and the closing lines written, exit 0.  Once the
loop has ended (whatever ended it), a stop request arriving while that end
is written used to abort it midway: "robstiff: terminated", exit 143, the
log folder without summary.json, the figures of a run that did happen lost
(seen once in CI at load: the service manager's SIGTERM and the loop's own
end close together).  ``EndHold`` is entered by the loop as it leaves
(cell/compensate.CompensatorLoop.run) and released by the command after its
report: a first request meanwhile is noted and said afterwards; a second
one is obeyed at once (an end that hangs, e.g. a log on a stalled disk,
is never kept alive against an operator who asks twice).  The robot is not
streamed to any more at that point: holding the request moves nothing.

Signals are Python's in the main thread only: elsewhere (a test calling the
loop from a worker thread) the hold does nothing."""

import signal
import threading

from robstiff_drake.errors import Terminated

_SIGNALS = (signal.SIGINT, signal.SIGTERM)
_NAMES = {signal.SIGINT: "Ctrl-C (SIGINT)", signal.SIGTERM: "SIGTERM"}


class EndHold:
    """Stop requests held from ``enter`` to ``release`` (see the module
    docstring).  ``noted``: the signal numbers noted, in order."""

    def __init__(self):
        self.noted = []
        self._old = None

    @property
    def held(self):
        return self._old is not None

    def enter(self):
        if self._old is not None or threading.current_thread() is not threading.main_thread():
            return self
        self._old = {s: signal.getsignal(s) for s in _SIGNALS}
        for s in _SIGNALS:
            signal.signal(s, self._note)
        return self

    def _note(self, signum, _frame):
        self.noted.append(signum)
        if len(self.noted) >= 2:  # asked again: obey now
            self.release()
            raise KeyboardInterrupt if signum == signal.SIGINT else Terminated()

    def release(self):
        """The handlers as before ``enter``; the requests noted are not
        raised again (the run has ended: what they asked is done)."""
        old = self._old
        if old is not None:
            for s, h in old.items():
                if h is not None:  # (None: a handler installed outside Python, which cannot be put back)
                    signal.signal(s, h)
            self._old = None  # (after: a request meanwhile still finds the hold and is noted)

    def said(self):
        """The line for the noted request (None when there was none)."""
        if not self.noted:
            return None
        return (f"{_NAMES.get(self.noted[0], f'signal {self.noted[0]}')} while the run's end was written: noted, "
                f"and the end (the log, summary.json) completed first")

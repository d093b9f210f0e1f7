"""A minimal headless-Chromium driver for the tests: Debian's chromium,
started with a fresh profile and no network of its own, driven over the
Chrome DevTools Protocol (a websocket on localhost) with websocket-client.

    with Chromium() as page:          # raises Unavailable when it cannot run
        page.open("file:///.../replay.html")
        value = page.wait_for("js expression", timeout_s=30)
        png_bytes = page.screenshot()

Nothing is downloaded: the browser is the system's package (``apt-get
install chromium``), or Unavailable says why not.
"""

import base64
import json
import shutil
import subprocess
import tempfile
import time
import urllib.request
from pathlib import Path

FLAGS = ("--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
         "--disable-background-networking", "--disable-component-update", "--disable-sync",
         "--window-size=1200,800", "--remote-debugging-port=0", "--remote-debugging-address=127.0.0.1")


class Unavailable(Exception):
    """Why the browser cannot be used here (the test skips with it)."""


def executable():
    for name in ("chromium", "chromium-browser"):
        path = shutil.which(name)
        if path:
            return path
    return None


class Chromium:
    def __init__(self, start_timeout_s=60.0):
        self.start_timeout_s = start_timeout_s
        self.proc = None
        self.ws = None
        self._id = 0
        self._profile = None

    def __enter__(self):
        exe = executable()
        if exe is None:
            raise Unavailable("no chromium on PATH (Debian: apt-get install chromium)")
        try:
            import websocket  # websocket-client, from the test extras
        except ImportError:
            raise Unavailable("the websocket-client package is missing (pip install -e '.[test]')") from None
        self._profile = tempfile.mkdtemp(prefix="robstiff-chromium-")
        self._log = open(Path(self._profile) / "chromium.log", "wb")  # a file: a full pipe would stall it
        self.proc = subprocess.Popen([exe, *FLAGS, f"--user-data-dir={self._profile}", "about:blank"],
                                     stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=self._log)
        try:
            port = self._port()
            url = self._page_websocket(port)
            self.ws = websocket.create_connection(url, timeout=30, suppress_origin=True)
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def _port(self):
        marker = Path(self._profile) / "DevToolsActivePort"
        deadline = time.monotonic() + self.start_timeout_s
        while time.monotonic() < deadline:
            if self.proc.poll() is not None:
                err = (Path(self._profile) / "chromium.log").read_text(errors="replace").strip().splitlines()
                raise Unavailable(f"chromium exited at start (status {self.proc.returncode}): "
                                  f"{err[-1] if err else 'no message'}")
            if marker.is_file() and marker.read_text().strip():
                return int(marker.read_text().split()[0])
            time.sleep(0.1)
        raise Unavailable(f"chromium did not open its DevTools port within {self.start_timeout_s:g} s")

    def _page_websocket(self, port):
        deadline = time.monotonic() + self.start_timeout_s
        while time.monotonic() < deadline:
            with urllib.request.urlopen(f"http://127.0.0.1:{port}/json/list", timeout=10) as r:
                pages = [t for t in json.load(r) if t.get("type") == "page"]
            if pages:
                return pages[0]["webSocketDebuggerUrl"]
            time.sleep(0.1)
        raise Unavailable("chromium has no page to drive")

    def call(self, method, **params):
        """One DevTools command; returns its result (events in between are skipped)."""
        self._id += 1
        self.ws.send(json.dumps({"id": self._id, "method": method, "params": params}))
        while True:
            msg = json.loads(self.ws.recv())
            if msg.get("id") == self._id:
                if "error" in msg:
                    raise RuntimeError(f"{method}: {msg['error']}")
                return msg["result"]

    def open(self, url):
        self.call("Page.enable")
        self.call("Page.navigate", url=url)

    def evaluate(self, expression):
        """The value of a JavaScript expression in the page (JSON-able), or
        raises with the page's exception."""
        r = self.call("Runtime.evaluate", expression=expression, returnByValue=True)
        if "exceptionDetails" in r:
            raise RuntimeError(r["exceptionDetails"].get("exception", {}).get("description", str(r)))
        return r["result"].get("value")

    def wait_for(self, expression, timeout_s=30.0):
        """Evaluate ``expression`` until it gives a truthy value; returns it
        (None after the timeout)."""
        deadline = time.monotonic() + timeout_s
        while time.monotonic() < deadline:
            try:
                value = self.evaluate(expression)
            except RuntimeError:
                value = None
            if value:
                return value
            time.sleep(0.2)
        return None

    def screenshot(self):
        """The page as PNG bytes."""
        return base64.b64decode(self.call("Page.captureScreenshot", format="png")["data"])

    def __exit__(self, exc_type, exc, tb):
        if self.ws is not None:
            try:
                self.ws.close()
            except OSError:
                pass
        if self.proc is not None and self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if getattr(self, "_log", None) is not None:
            self._log.close()
        if self._profile:
            shutil.rmtree(self._profile, ignore_errors=True)
        return False

"""
A headless Chromium driven over the DevTools protocol, for the HTML page tests.

Standard library only: the browser is Debian's ``chromium`` (``make test`` installs it with
apt when it can), started with ``--remote-debugging-port=0``; the port it chose is read from
``DevToolsActivePort`` in its fresh profile folder, and this module speaks the WebSocket
protocol (RFC 6455: client frames masked, server frames not) to it itself, so no Python package
and no browser download is needed.  One browser serves a whole test module; each page gets a new
tab (:meth:`Chromium.open`) with the network emulated offline and every request recorded.
"""

import base64
import itertools
import json
import os
from pathlib import Path
import shutil
import socket
import struct
import subprocess
import tempfile
import time

#: Flags that work in a container as root with no display, GPU, network or D-Bus.
FLAGS = ('--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
         '--disable-background-networking', '--disable-component-update', '--disable-sync',
         '--disable-extensions', '--disable-default-apps', '--mute-audio',
         '--hide-scrollbars', '--remote-debugging-port=0', '--remote-allow-origins=*')
START_TIMEOUT_S = 30.0


def find_chromium():
    """Return the path of a Chromium executable, or None (the tests then skip saying why)."""
    for name in ('chromium', 'chromium-browser', 'google-chrome', 'google-chrome-stable'):
        path = shutil.which(name)
        if path:
            return path
    return None


class WebSocket:
    """The client side of one WebSocket connection (text messages; ping answered)."""

    def __init__(self, url, timeout=30.0):
        """Connect to ``ws://host:port/path`` and complete the opening handshake."""
        rest = url[len('ws://'):]
        hostport, _, path = rest.partition('/')
        host, _, port = hostport.partition(':')
        self.sock = socket.create_connection((host, int(port)), timeout=timeout)
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f'GET /{path} HTTP/1.1\r\nHost: {hostport}\r\nUpgrade: websocket\r\n'
                           f'Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n'
                           f'Sec-WebSocket-Version: 13\r\n\r\n').encode())
        head = b''
        while b'\r\n\r\n' not in head:
            chunk = self.sock.recv(4096)
            if not chunk:
                raise ConnectionError('closed during the WebSocket handshake')
            head += chunk
        status, _, self.buffer = head.partition(b'\r\n\r\n')
        if b' 101 ' not in status.split(b'\r\n')[0]:
            raise ConnectionError(f'WebSocket handshake refused: {status[:200]!r}')

    def _read(self, n):
        while len(self.buffer) < n:
            chunk = self.sock.recv(1 << 20)
            if not chunk:
                raise ConnectionError('WebSocket closed by the browser')
            self.buffer += chunk
        out, self.buffer = self.buffer[:n], self.buffer[n:]
        return out

    def _send_frame(self, opcode, payload):
        head = bytes([0x80 | opcode])
        n = len(payload)
        if n < 126:
            head += bytes([0x80 | n])
        elif n < 1 << 16:
            head += bytes([0x80 | 126]) + struct.pack('!H', n)
        else:
            head += bytes([0x80 | 127]) + struct.pack('!Q', n)
        mask = os.urandom(4)
        # XOR with the repeated mask as one big integer: fast enough for any message here
        stream = (mask * (n // 4 + 1))[:n]
        masked = (int.from_bytes(payload, 'big') ^ int.from_bytes(stream, 'big')).to_bytes(
            n, 'big') if n else b''
        self.sock.sendall(head + mask + masked)

    def send(self, text):
        """Send one text message."""
        self._send_frame(0x1, text.encode('utf-8'))

    def recv(self):
        """Return the next text message (fragments joined, pings answered)."""
        parts = []
        while True:
            b0, b1 = self._read(2)
            opcode, n = b0 & 0x0F, b1 & 0x7F
            if n == 126:
                n = struct.unpack('!H', self._read(2))[0]
            elif n == 127:
                n = struct.unpack('!Q', self._read(8))[0]
            mask = self._read(4) if b1 & 0x80 else None
            payload = self._read(n)
            if mask:
                payload = bytes(c ^ mask[i % 4] for i, c in enumerate(payload))
            if opcode == 0x9:
                self._send_frame(0xA, payload)
                continue
            if opcode == 0x8:
                raise ConnectionError('WebSocket closed by the browser')
            if opcode in (0x0, 0x1, 0x2):
                parts.append(payload)
                if b0 & 0x80:
                    return b''.join(parts).decode('utf-8')

    def close(self):
        """Close the TCP connection."""
        self.sock.close()


class Chromium:
    """A headless Chromium process and a DevTools connection to it (a context manager)."""

    def __init__(self, executable):
        """Start the browser with a new profile folder; connect to its DevTools endpoint."""
        self.profile = tempfile.mkdtemp(prefix='imu_allan_chromium_')
        self.proc = subprocess.Popen([executable, *FLAGS, f'--user-data-dir={self.profile}',
                                      'about:blank'],
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        port_file = Path(self.profile) / 'DevToolsActivePort'
        end = time.monotonic() + START_TIMEOUT_S
        while not (port_file.is_file() and len(port_file.read_text().split('\n')) >= 2):
            if self.proc.poll() is not None or time.monotonic() > end:
                self.close()
                raise RuntimeError(f'{executable} did not open its DevTools port')
            time.sleep(0.05)
        port, path = port_file.read_text().split('\n')[:2]
        self.ws = WebSocket(f'ws://127.0.0.1:{port}{path}')
        self.ids = itertools.count(1)
        self.events = []

    def __enter__(self):
        """Return the browser."""
        return self

    def __exit__(self, *exc):
        """Close the browser."""
        self.close()
        return False

    def close(self):
        """Stop the browser process (this test's own) and remove its profile."""
        if getattr(self, 'ws', None) is not None:
            self.ws.close()
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=10)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        shutil.rmtree(self.profile, ignore_errors=True)

    def call(self, method, session=None, **params):
        """Send one DevTools command and return its result; events meanwhile are kept."""
        msg_id = next(self.ids)
        msg = {'id': msg_id, 'method': method, 'params': params}
        if session:
            msg['sessionId'] = session
        self.ws.send(json.dumps(msg))
        while True:
            reply = json.loads(self.ws.recv())
            if reply.get('id') == msg_id:
                if 'error' in reply:
                    raise RuntimeError(f'{method}: {reply["error"]}')
                return reply.get('result', {})
            self.events.append(reply)

    def wait_event(self, method, session, timeout=30.0):
        """Return the first event ``method`` of ``session`` (kept or still to come)."""
        end = time.monotonic() + timeout
        while True:
            for ev in self.events:
                if ev.get('method') == method and ev.get('sessionId') == session:
                    return ev
            if time.monotonic() > end:
                raise TimeoutError(f'no {method} within {timeout} s')
            self.events.append(json.loads(self.ws.recv()))

    def open_page(self, url, width=1280, height=900):
        """Load ``url`` in a new tab, offline, ``width`` px wide; return a :class:`Page`."""
        target = self.call('Target.createTarget', url='about:blank')['targetId']
        session = self.call('Target.attachToTarget', targetId=target, flatten=True)['sessionId']
        for domain in ('Page', 'Runtime', 'Log', 'Network'):
            self.call(f'{domain}.enable', session)
        self.call('Network.emulateNetworkConditions', session, offline=True, latency=0,
                  downloadThroughput=-1, uploadThroughput=-1)
        self.call('Emulation.setDeviceMetricsOverride', session, width=width, height=height,
                  deviceScaleFactor=1, mobile=False)
        self.events.clear()
        self.call('Page.navigate', session, url=url)
        self.wait_event('Page.loadEventFired', session)
        return Page(self, session, target)


class Page:
    """One loaded tab: evaluate JavaScript, screenshot, and what happened while loading."""

    def __init__(self, browser, session, target):
        """Keep the browser, the DevTools session and the target id."""
        self.browser, self.session, self.target = browser, session, target

    def evaluate(self, expression):
        """Return the value of a JavaScript expression (awaited if a promise)."""
        result = self.browser.call('Runtime.evaluate', self.session, expression=expression,
                                   returnByValue=True, awaitPromise=True)
        if 'exceptionDetails' in result:
            raise RuntimeError(f'JavaScript error: {result["exceptionDetails"]}')
        return result['result'].get('value')

    def _events(self, method):
        return [e['params'] for e in self.browser.events
                if e.get('method') == method and e.get('sessionId') == self.session]

    def requests(self):
        """Return the URLs of every request the page made."""
        return [e['request']['url'] for e in self._events('Network.requestWillBeSent')]

    def console_errors(self):
        """Console errors, uncaught exceptions and error log entries, as text."""
        errors = [' '.join(str(a.get('value', a.get('description', ''))) for a in e['args'])
                  for e in self._events('Runtime.consoleAPICalled') if e['type'] == 'error']
        errors += [e['exceptionDetails'].get('text', '')
                   for e in self._events('Runtime.exceptionThrown')]
        errors += [f'{e["entry"]["source"]}: {e["entry"]["text"]}'
                   for e in self._events('Log.entryAdded') if e['entry']['level'] == 'error']
        return errors

    def screenshot(self):
        """PNG bytes of the whole page (its full height) at the tab's width."""
        size = self.browser.call('Page.getLayoutMetrics', self.session)['cssContentSize']
        clip = {'x': 0, 'y': 0, 'width': size['width'], 'height': size['height'], 'scale': 1}
        shot = self.browser.call('Page.captureScreenshot', self.session, format='png',
                                 clip=clip, captureBeyondViewport=True)
        return base64.b64decode(shot['data'])

    def close(self):
        """Close the tab."""
        self.browser.call('Target.closeTarget', targetId=self.target)

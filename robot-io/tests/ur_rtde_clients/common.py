"""Shared helpers for the ur_rtde client tests (issue 11).

The emulator is started by scripts/test-ur-rtde on loopback with UR's ports (ur_rtde's
receive and IO interfaces always use 30004). HRC_EMU_MODE says which backend it runs
("sim" or "trace"). No assertion depends on wall-clock speed: waits poll with generous
bounds, and what is checked is what the packages say.
"""

import os
import socket
import struct
import time

HOST = os.environ.get("HRC_EMU_HOST", "127.0.0.1")
DASHBOARD_PORT = int(os.environ.get("HRC_EMU_DASHBOARD_PORT", "29999"))
MODE = os.environ.get("HRC_EMU_MODE", "sim")
# Generous bound on any wait [s] (a loaded 2-core CI machine).
PATIENCE_S = 30.0


def wait_until(predicate, what, patience=PATIENCE_S, poll=0.01):
    """Polls `predicate` until it is truthy; fails after `patience` seconds."""
    deadline = time.monotonic() + patience
    while True:
        value = predicate()
        if value:
            return value
        if time.monotonic() > deadline:
            raise AssertionError("timed out waiting for " + what)
        time.sleep(poll)


class RawRtde:
    """A minimal RTDE reader of our own (protocol 2), for what ur_rtde's receive interface
    cannot read: the input registers ur_rtde's IO interface writes."""

    TYPES = {"INT32": (">i", 4), "DOUBLE": (">d", 8), "UINT8": (">B", 1),
             "UINT32": (">I", 4), "UINT64": (">Q", 8), "BOOL": (">?", 1)}

    def __init__(self, port=30004):
        self.sock = socket.create_connection((HOST, port), timeout=PATIENCE_S)
        self.buf = b""
        assert self.request("V", struct.pack(">H", 2)) == b"\x01"

    def send(self, kind, payload=b""):
        self.sock.sendall(struct.pack(">HB", 3 + len(payload), ord(kind)) + payload)

    def recv(self):
        while True:
            while len(self.buf) < 3:
                self.buf += self._more()
            size, kind = struct.unpack(">HB", self.buf[:3])
            while len(self.buf) < size:
                self.buf += self._more()
            pkg, self.buf = self.buf[:size], self.buf[size:]
            if chr(kind) != "M":
                return chr(kind), pkg[3:]

    def _more(self):
        d = self.sock.recv(65536)
        if not d:
            raise AssertionError("emulator closed the RTDE connection")
        return d

    def request(self, kind, payload=b""):
        self.send(kind, payload)
        while True:
            k, p = self.recv()
            if k == kind:
                return p

    def setup_outputs(self, names, frequency=500.0):
        reply = self.request("O", struct.pack(">d", frequency) + ",".join(names).encode())
        self.types = reply[1:].decode().split(",")
        return reply[0], self.types

    def start(self):
        assert self.request("S") == b"\x01"

    def sample(self):
        while True:
            k, p = self.recv()
            if k == "U":
                out, at = [], 1
                for t in self.types:
                    fmt, n = self.TYPES[t]
                    out.append(struct.unpack(fmt, p[at:at + n])[0])
                    at += n
                return out

    def close(self):
        self.sock.close()


class Dashboard:
    """Raw dashboard lines (for replies ur_rtde's client does not return)."""

    def __init__(self):
        self.sock = socket.create_connection((HOST, DASHBOARD_PORT), timeout=PATIENCE_S)
        self.f = self.sock.makefile("rwb")
        self.greeting = self.f.readline().decode().strip()

    def ask(self, line):
        self.f.write((line + "\n").encode())
        self.f.flush()
        return self.f.readline().decode().strip()

    def close(self):
        self.sock.close()

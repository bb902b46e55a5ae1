#!/usr/bin/env python3
"""Issue 11's hostile-client figures: does `hrc-adapt emulate --sim` keep serving a
well-behaved client, with bounded memory, while other clients misbehave?

Starts the emulator on ephemeral loopback ports, then times a **well-behaved job**:
  - RTDE: connect, negotiate protocol 2, set up a 500 Hz output recipe (timestamp, actual_q),
    start, and receive 2500 data packages (5 s of controller time); its wall time and the largest
    gap between two packages;
  - dashboard: 200 `robotmode` request/reply round trips; their wall time.
First alone (quiet, 3 times), then while, all at once and for about 20 s:
  - garbage: 4 clients streaming random bytes at the RTDE port and 4 at the dashboard port;
  - oversized packets: 4 clients sending RTDE headers that claim 65 535 bytes (a setup-outputs
    package) and then a megabyte of payload;
  - 2000 connects in 20 s to the RTDE port, each closed at once;
  - 100 stalled clients: each sets up a 500 Hz recipe, starts, and never reads;
  - one 64 MiB dashboard line without a newline.
The emulator's resident memory (VmRSS, VmHWM from /proc) is read before, during and after.

Prints a Markdown table for BENCHMARKS.md. A measurement, not a test: it asserts nothing about
time and judges nothing; the caller reads the figures. Every load is on 127.0.0.1 only, bounded
in count and time, and stops by itself.

    scripts/bench/emulator_hostile.py [--bin target/release/hrc-adapt] [--only LOAD ...] [--sink] [--pin]
"""

import argparse
import multiprocessing
import os
import random
import re
import socket
import struct
import subprocess
import sys
import threading
import time

HOST = "127.0.0.1"


def rtde_send(sock, kind, payload=b""):
    sock.sendall(struct.pack(">HB", 3 + len(payload), ord(kind)) + payload)


def rtde_recv(sock):
    head = recv_exact(sock, 3)
    size, kind = struct.unpack(">HB", head)
    return chr(kind), recv_exact(sock, size - 3)


def recv_exact(sock, n):
    buf = b""
    while len(buf) < n:
        chunk = sock.recv(n - len(buf))
        if not chunk:
            raise ConnectionError("closed")
        buf += chunk
    return buf


def rtde_stream(port, fields=b"timestamp,actual_q", hz=500.0, timeout=10.0):
    """Connects, negotiates protocol 2, sets up and starts a recipe; returns the socket."""
    s = socket.create_connection((HOST, port), timeout=timeout)
    s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    rtde_send(s, "V", struct.pack(">H", 2))
    kind, body = rtde_recv(s)
    if kind != "V" or body[0] != 1:
        raise RuntimeError(f"protocol 2 refused: {kind} {body!r}")
    rtde_send(s, "O", struct.pack(">d", hz) + fields)
    kind, body = rtde_recv(s)
    if kind != "O" or body[0] == 0:
        raise RuntimeError(f"recipe refused: {kind} {body!r}")
    rtde_send(s, "S")
    kind, body = rtde_recv(s)
    if kind != "S" or body[0] != 1:
        raise RuntimeError(f"start refused: {kind} {body!r}")
    return s


def rtde_job(port, packages=2500):
    """The well-behaved RTDE job: (wall time [s], largest gap between packages [s])."""
    t0 = time.monotonic()
    s = rtde_stream(port)
    got, last, gap = 0, None, 0.0
    while got < packages:
        kind, _ = rtde_recv(s)
        if kind != "U":
            continue
        now = time.monotonic()
        if last is not None:
            gap = max(gap, now - last)
        last = now
        got += 1
    s.close()
    return time.monotonic() - t0, gap


def dashboard_job(port, n=200):
    """The well-behaved dashboard job: wall time [s] of `n` round trips."""
    t0 = time.monotonic()
    s = socket.create_connection((HOST, port), timeout=10.0)
    f = s.makefile("rb")
    f.readline()  # greeting
    for _ in range(n):
        s.sendall(b"robotmode\n")
        if not f.readline():
            raise ConnectionError("dashboard closed")
    s.close()
    return time.monotonic() - t0


def memory_kib(pid):
    """(VmRSS, VmHWM) [KiB] of `pid`."""
    out = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith(("VmRSS:", "VmHWM:")):
                key, value = line.split(":")
                out[key] = int(value.split()[0])
    return out["VmRSS"], out["VmHWM"]


class Load:
    """The hostile clients, each a thread that stops at `deadline` (monotonic)."""

    def __init__(self, rtde, dash, seconds, only=None, sink=None):
        self.rtde, self.dash = rtde, dash
        self.sink = sink  # --sink: the garbage goes to a discard server instead
        self.only = only
        self.deadline = time.monotonic() + seconds
        self.counts = {"garbage bytes": 0, "oversized": 0, "connects": 0, "stalled": 0, "long line bytes": 0}
        self.errors = {}
        self.lock = threading.Lock()
        self.threads = []
        self.stalled = []

    def count(self, key, n=1):
        with self.lock:
            self.counts[key] += n

    def error(self, what, e):
        with self.lock:
            self.errors[f"{what}: {type(e).__name__}"] = self.errors.get(f"{what}: {type(e).__name__}", 0) + 1

    def spawn(self, fn, *args):
        t = threading.Thread(target=fn, args=args, daemon=True)
        t.start()
        self.threads.append(t)

    def garbage(self, port):
        rnd = random.Random(port)
        while time.monotonic() < self.deadline:
            try:
                s = socket.create_connection((HOST, port), timeout=2.0)
                for _ in range(64):
                    if time.monotonic() >= self.deadline:
                        break
                    chunk = rnd.randbytes(4096)
                    s.sendall(chunk)
                    self.count("garbage bytes", len(chunk))
                s.close()
            except OSError as e:  # the emulator may close a garbage sender: reconnect
                self.error("garbage", e)
                time.sleep(0.01)

    def oversized(self):
        payload = b"x" * 65_532
        while time.monotonic() < self.deadline:
            try:
                s = socket.create_connection((HOST, self.rtde), timeout=2.0)
                for _ in range(16):
                    s.sendall(struct.pack(">HB", 0xFFFF, ord("O")) + payload)
                    self.count("oversized")
                s.close()
            except OSError as e:
                self.error("oversized", e)
                time.sleep(0.01)

    def connects(self, n, seconds):
        start = time.monotonic()
        for i in range(n):
            due = start + i * seconds / n
            time.sleep(max(0.0, due - time.monotonic()))
            try:
                socket.create_connection((HOST, self.rtde), timeout=2.0).close()
                self.count("connects")
            except OSError as e:
                self.error("connect", e)

    def stall(self, n):
        for _ in range(n):
            try:
                self.stalled.append(rtde_stream(self.rtde))  # never read again
                self.count("stalled")
            except (OSError, RuntimeError, ConnectionError) as e:
                self.error("stalled", e)

    def long_line(self, mib):
        try:
            s = socket.create_connection((HOST, self.dash), timeout=5.0)
            block = b"a" * (1 << 20)
            for _ in range(mib):
                s.sendall(block)
                self.count("long line bytes", len(block))
            s.close()
        except OSError as e:
            self.error("long line", e)

    def start(self):
        on = lambda name: self.only is None or name in self.only  # noqa: E731
        for _ in range(4):
            if on("garbage-rtde"):
                self.spawn(self.garbage, self.sink or self.rtde)
            if on("garbage-dashboard"):
                self.spawn(self.garbage, self.sink or self.dash)
            if on("oversized"):
                self.spawn(self.oversized)
        if on("connects"):
            self.spawn(self.connects, 2000, 20.0)
        if on("stalled"):
            self.spawn(self.stall, 100)
        if on("long-line"):
            self.spawn(self.long_line, 64)

    def join(self):
        for t in self.threads:
            t.join()
        for s in self.stalled:
            s.close()


def run_load(rtde, dash, seconds, only, out, sink=None, cpus=None):
    """The whole load in a process of its own (its threads share one GIL, the timed jobs must
    not: Python's 5 ms GIL switch interval would be measured as the emulator's latency)."""
    if cpus is not None:
        os.sched_setaffinity(0, cpus)
    load = Load(rtde, dash, seconds, only, sink)
    load.start()
    load.join()
    out.put((load.counts, load.errors))


def discard_server(sock):
    """Reads and drops whatever each client sends, until it closes (the --sink control)."""
    def serve(c):
        with c:
            while c.recv(1 << 16):
                pass
    while True:
        c, _ = sock.accept()
        threading.Thread(target=serve, args=(c,), daemon=True).start()


def start_sink():
    sock = socket.socket()
    sock.bind((HOST, 0))
    sock.listen(64)
    p = multiprocessing.Process(target=discard_server, args=(sock,), daemon=True)
    p.start()
    return p, sock.getsockname()[1]


def start_emulator(binary):
    p = subprocess.Popen(
        [binary, "emulate", "--sim", "--speedup", "1", "--rtde-port", "0", "--dashboard-port", "0",
         "--secondary-port", "0", "--realtime-port", "0"],
        stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
        env={**os.environ, "RUST_LOG": "warn"})
    for line in p.stderr:
        if line.startswith("emulating a UR controller"):
            ports = {k: int(re.search(rf"{k}\s+[\d.]+:(\d+)", line).group(1)) for k in ("rtde", "dashboard")}
            threading.Thread(target=lambda: [None for _ in p.stderr], daemon=True).start()
            return p, ports["rtde"], ports["dashboard"]
    raise RuntimeError("the emulator did not start")


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--bin", default="target/release/hrc-adapt")
    ap.add_argument("--only", nargs="+", choices=["garbage-rtde", "garbage-dashboard", "oversized",
                                                  "connects", "stalled", "long-line"],
                    help="run only these loads (default: all at once)")
    ap.add_argument("--sink", action="store_true",
                    help="control run: the garbage senders send to a discard server of their own (another "
                         "process) instead of the emulator, so only their CPU use competes")
    ap.add_argument("--pin", action="store_true",
                    help="the emulator and the timed jobs on the first CPU, the load on the others, in "
                         "every phase: the load's own CPU use then does not compete with the emulator")
    args = ap.parse_args()
    sink_proc, sink = start_sink() if args.sink else (None, None)
    load_cpus = None
    if args.pin:
        # The emulator (inherits this) and the timed jobs on CPU 0, the load on the others.
        cpus = sorted(os.sched_getaffinity(0))
        if len(cpus) < 2:
            sys.exit("--pin needs two CPUs")
        os.sched_setaffinity(0, {cpus[0]})
        load_cpus = set(cpus[1:])
    emu, rtde, dash = start_emulator(args.bin)
    try:
        time.sleep(1.0)
        rows = []
        mem0 = memory_kib(emu.pid)
        for i in range(3):
            t, gap = rtde_job(rtde)
            rows.append(("quiet", i + 1, t, gap, dashboard_job(dash)))
        mem_quiet = memory_kib(emu.pid)
        results = multiprocessing.Queue()
        loader = multiprocessing.Process(target=run_load, args=(rtde, dash, 20.0, args.only, results, sink, load_cpus))
        deadline = time.monotonic() + 20.0
        loader.start()
        peak = mem_quiet
        i = 0
        while time.monotonic() < deadline:
            t, gap = rtde_job(rtde)
            d = dashboard_job(dash)
            i += 1
            rows.append(("hostile", i, t, gap, d))
            peak = max(peak, memory_kib(emu.pid))
        counts, errors = results.get(timeout=120)
        loader.join()
        time.sleep(12.0)  # past the 10 s stall timeout: stalled clients dropped
        mem_after = memory_kib(emu.pid)
        t, gap = rtde_job(rtde)
        rows.append(("after", 1, t, gap, dashboard_job(dash)))
        alive = emu.poll() is None
    finally:
        emu.terminate()
        emu.wait(timeout=10)
        if sink_proc is not None:
            sink_proc.terminate()
            sink_proc.join(timeout=10)

    quiet = [r for r in rows if r[0] == "quiet"]
    hostile = [r for r in rows if r[0] == "hostile"]
    q_rtde = sorted(r[2] for r in quiet)[1]
    q_dash = sorted(r[4] for r in quiet)[1]
    print("| phase | run | RTDE job [s] (2500 packages at 500 Hz) | largest gap [ms] | dashboard job [s] (200 round trips) |")
    print("|---|---|---|---|---|")
    for phase, i, t, gap, d in rows:
        print(f"| {phase} | {i} | {t:.3f} | {gap * 1e3:.1f} | {d:.3f} |")
    print()
    print(f"quiet medians: RTDE {q_rtde:.3f} s, dashboard {q_dash:.3f} s; "
          f"hostile worst: RTDE {max(r[2] for r in hostile):.3f} s "
          f"({max(r[2] for r in hostile) / q_rtde:.2f} x), dashboard {max(r[4] for r in hostile):.3f} s "
          f"({max(r[4] for r in hostile) / q_dash:.2f} x)")
    print(f"memory [MiB] (VmRSS): start {mem0[0] / 1024:.1f}, after the quiet runs {mem_quiet[0] / 1024:.1f}, "
          f"peak during the load {peak[0] / 1024:.1f} (VmHWM {peak[1] / 1024:.1f}), 12 s after it {mem_after[0] / 1024:.1f}")
    print(f"load sent: {counts}")
    print(f"load errors (the emulator closing a misbehaving client shows here): {errors}")
    print(f"emulator still running at the end: {alive}")


if __name__ == "__main__":
    sys.exit(main())

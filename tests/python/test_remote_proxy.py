"""Tests of wmo.remote.proxy, the latency-injecting TCP proxy.

Everything runs on loopback against small threaded servers on port 0, and every blocking
call has a timeout, so a bug fails a test instead of hanging the suite. Timing asserts
have a tight lower bound (the proxy must never deliver early: its due times are computed,
and asyncio timers do not fire early) and a generous upper bound (a loaded 2-core CI
machine can delay a thread by tens of milliseconds)."""
from __future__ import annotations

import asyncio
import logging
import math
import os
import random
import signal
import socket
import statistics
import subprocess
import sys
import threading
import time

import pytest

from wmo.remote import proxy as proxy_mod
from wmo.remote.proxy import PRESETS, LatencyProxy, main, parse_bandwidth, parse_duration

# Upper-bound slack for timing asserts, seconds: scheduling noise on a loaded CI machine.
SLACK = 0.08
# Lower-bound slack, seconds: clock granularity between the proxy's and the test's clock
# readings (both monotonic), not scheduling noise.
EARLY = 0.005
IO_TIMEOUT = 10.0  # no single socket operation in these tests should take this long


# ----------------------------------------------------------------------------- helpers

class TcpServer:
    """A threaded TCP server on 127.0.0.1:0 running handler(conn) per connection."""

    def __init__(self, handler):
        self.handler = handler
        self.sock = socket.create_server(("127.0.0.1", 0))
        self.sock.settimeout(0.05)  # so the accept loop notices close()
        self.port = self.sock.getsockname()[1]
        self.conns: list[socket.socket] = []
        self.closed = threading.Event()
        self.thread = threading.Thread(target=self._accept_loop, daemon=True)
        self.thread.start()

    def _accept_loop(self):
        while not self.closed.is_set():
            try:
                conn, _ = self.sock.accept()
            except socket.timeout:
                continue
            except OSError:
                return
            conn.settimeout(IO_TIMEOUT)
            conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            self.conns.append(conn)
            threading.Thread(target=self._serve, args=(conn,), daemon=True).start()

    def _serve(self, conn):
        try:
            self.handler(conn)
        except OSError:
            pass
        finally:
            conn.close()

    def close(self):
        self.closed.set()
        self.thread.join(2)
        self.sock.close()
        for conn in self.conns:
            try:
                conn.shutdown(socket.SHUT_RDWR)
            except OSError:
                pass
            conn.close()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()


def echo(conn):
    """Echo everything; on EOF, half-close back (so EOF propagation is visible)."""
    while True:
        data = conn.recv(65536)
        if not data:
            break
        conn.sendall(data)
    conn.shutdown(socket.SHUT_WR)


def recv_exact(sock, n):
    parts, got = [], 0
    while got < n:
        data = sock.recv(min(65536, n - got))
        if not data:
            raise EOFError(f"EOF after {got} of {n} bytes")
        parts.append(data)
        got += len(data)
    return b"".join(parts)


def recv_all(sock):
    parts = []
    while True:
        data = sock.recv(65536)
        if not data:
            return b"".join(parts)
        parts.append(data)


def connect(port):
    sock = socket.create_connection(("127.0.0.1", port), timeout=IO_TIMEOUT)
    # No Nagle: small pings go out at once, so a round trip measures the proxy only.
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    return sock


def rtt(sock, size=16):
    msg = os.urandom(size)
    t0 = time.monotonic()
    sock.sendall(msg)
    assert recv_exact(sock, size) == msg
    return time.monotonic() - t0


def median_rtt(sock, n=5):
    rtt(sock)  # warm-up: the first round trip includes the proxy's connect to the target
    return statistics.median(rtt(sock) for _ in range(n))


def send_in_background(sock, pieces, pause=0.0, shutdown=True):
    """Send `pieces` on a thread (so the test can read concurrently without the two
    directions' buffers deadlocking); half-close afterwards."""
    errors = []

    def run():
        try:
            for p in pieces:
                sock.sendall(p)
                if pause:
                    time.sleep(pause)
            if shutdown:
                sock.shutdown(socket.SHUT_WR)
        except OSError as exc:
            errors.append(exc)

    t = threading.Thread(target=run, daemon=True)
    t.start()
    return t, errors


def random_pieces(rng, total, max_piece):
    data = rng.randbytes(total)
    pieces, i = [], 0
    while i < total:
        n = rng.randint(1, max_piece)
        pieces.append(data[i:i + n])
        i += n
    return data, pieces


def sees_closed(sock, timeout=3.0):
    """True if `sock` sees EOF or a reset within `timeout` seconds (data is drained)."""
    sock.settimeout(timeout)
    try:
        while sock.recv(65536):
            pass
        return True
    except (ConnectionResetError, ConnectionAbortedError, BrokenPipeError):
        return True
    except socket.timeout:
        return False


@pytest.fixture
def echo_server():
    with TcpServer(echo) as server:
        yield server


@pytest.fixture(autouse=True)
def no_proxy_errors(caplog):
    """Fails any test in which the proxy or asyncio logged an error (an exception that
    leaked out of a task or callback on the proxy's thread)."""
    caplog.set_level(logging.WARNING)
    yield
    # caplog.records holds only the current phase's records; the test ran in "call".
    records = caplog.get_records("setup") + caplog.get_records("call")
    bad = [r for r in records
           if r.levelno >= logging.ERROR and r.name.startswith(("asyncio", "wmo"))]
    assert not bad, [r.getMessage() for r in bad]


# -------------------------------------------------------------- the scheduling model

def settings(**kw):
    base = dict(delay=0.0, jitter=0.0, loss=0.0, bandwidth=None, retransmit_timeout=0.2)
    base.update(kw)
    return proxy_mod._Settings(**base)


def test_link_model_jitter_never_reorders_and_stays_within_bounds():
    link = proxy_mod._Link(random.Random(1))
    s = settings(delay=0.02, jitter=0.05)
    dues = []
    for i in range(1000):
        now = i * 0.001  # chunks 1 ms apart, far closer than the 50 ms jitter
        due, lost = link.schedule(now, 100, s)
        assert not lost
        assert due >= now + 0.02               # never less than the delay
        dues.append(due)
    assert all(b >= a for a, b in zip(dues, dues[1:]))
    # Isolated chunks (far apart) see the full uniform [delay, delay + jitter) range.
    link = proxy_mod._Link(random.Random(2))
    extras = [link.schedule(i * 1.0, 100, s)[0] - i * 1.0 - 0.02 for i in range(2000)]
    assert 0 <= min(extras) < 0.002 and 0.048 < max(extras) < 0.05
    assert statistics.mean(extras) == pytest.approx(0.025, abs=0.002)


def test_link_model_bandwidth_serialises_and_queues():
    link = proxy_mod._Link(random.Random(0))
    s = settings(delay=0.01, bandwidth=1000.0)
    assert link.schedule(0.0, 100, s)[0] == pytest.approx(0.1 + 0.01)
    # Arrives while the link is still busy: queues behind the first chunk.
    assert link.schedule(0.05, 100, s)[0] == pytest.approx(0.2 + 0.01)
    # Arrives when the link is idle: starts at once.
    assert link.schedule(1.0, 50, s)[0] == pytest.approx(1.05 + 0.01)
    # The end of the stream follows the last byte over the link.
    assert link.schedule_eof(1.0, s) == pytest.approx(1.05 + 0.01)


def test_link_model_loss_is_late_delivery_with_head_of_line_blocking():
    class Draws:  # a stand-in generator whose random() returns a scripted sequence
        def __init__(self, values):
            self.values = iter(values)

        def random(self):
            return next(self.values)

    # Per chunk: (jitter draw, loss draw). Chunk 0 lost (0.0 < loss), chunk 1 not.
    link = proxy_mod._Link(Draws([0.5, 0.0, 0.5, 0.9]))
    s = settings(delay=0.03, loss=0.5, retransmit_timeout=0.1)
    due0, lost0 = link.schedule(0.0, 10, s)
    due1, lost1 = link.schedule(0.001, 10, s)
    assert lost0 and not lost1
    assert due0 == pytest.approx(0.03 + 0.1)    # max(rto 0.1, 2 * delay 0.06)
    assert due1 == pytest.approx(due0)          # held back behind the "retransmission"
    # With a delay long enough, the round trip (2 * delay) dominates the timeout.
    link = proxy_mod._Link(Draws([0.5, 0.0]))
    due, lost = link.schedule(0.0, 10, settings(delay=0.2, loss=0.5, retransmit_timeout=0.1))
    assert lost and due == pytest.approx(0.2 + 0.4)


# ------------------------------------------------------------------- pass-through

@pytest.mark.parametrize("kw", [{}, {"delay": 0.002, "jitter": 0.003, "seed": 5}],
                         ids=["plain", "delay+jitter"])
def test_pass_through_is_intact_and_in_order_both_ways(echo_server, kw):
    rng = random.Random(42)
    data, pieces = random_pieces(rng, 1_000_000, 20_000)
    with LatencyProxy("127.0.0.1", echo_server.port, **kw) as proxy:
        with connect(proxy.port) as sock:
            sender, errors = send_in_background(sock, pieces)
            received = recv_all(sock)  # EOF: our half-close went up, the echo's came down
            sender.join(IO_TIMEOUT)
        assert not errors
        assert len(received) == len(data) and received == data
        st = proxy.stats
    assert st["bytes_up"] == st["bytes_down"] == len(data)
    assert st["connections"] == 1 and st["failed"] == 0 and st["lost_up"] == 0


# ------------------------------------------------------------------------- timing

def test_delay_adds_twice_the_delay_to_the_round_trip(echo_server):
    with LatencyProxy("127.0.0.1", echo_server.port) as proxy, connect(proxy.port) as sock:
        base = median_rtt(sock)
    delay = 0.05
    with LatencyProxy("127.0.0.1", echo_server.port, delay=delay) as proxy, \
            connect(proxy.port) as sock:
        delayed = median_rtt(sock)
    added = delayed - base
    print(f"baseline rtt {base * 1e3:.2f} ms, with delay {delay}: {delayed * 1e3:.2f} ms, "
          f"added {added * 1e3:.2f} ms")
    # Each direction holds every chunk for at least `delay`: the lower bound is exact up
    # to clock granularity; the upper bound allows for CI scheduling noise.
    assert 2 * delay - EARLY <= added <= 2 * delay + SLACK


def test_jitter_never_reorders(echo_server):
    # 300 small messages 1 ms apart with up to 30 ms of jitter: without the ordering rule
    # most of them would overtake one another.
    messages = [f"<{i:05d}>".encode() for i in range(300)]
    with LatencyProxy("127.0.0.1", echo_server.port, delay=0.005, jitter=0.03,
                      seed=7) as proxy, connect(proxy.port) as sock:
        sender, errors = send_in_background(sock, messages, pause=0.001)
        received = recv_all(sock)
        sender.join(IO_TIMEOUT)
        st = proxy.stats
    assert not errors
    assert received == b"".join(messages)
    assert st["chunks_up"] > 50  # the messages really went through as many chunks


def test_loss_delivers_everything_late_and_in_order(echo_server):
    rto = 0.1
    with LatencyProxy("127.0.0.1", echo_server.port, loss=0.2, retransmit_timeout=rto,
                      seed=3) as proxy, connect(proxy.port) as sock:
        # Ping-pong: each message is one chunk each way, so every lost chunk adds exactly
        # one retransmission delay to the total.
        t0 = time.monotonic()
        rtts = [rtt(sock, 64) for _ in range(25)]
        total = time.monotonic() - t0
        st = proxy.stats
        lost = st["lost_up"] + st["lost_down"]
        assert st["chunks_up"] == st["chunks_down"] == 25
        print(f"lost {lost} of 50 chunks; ping-pong total {total:.3f} s; "
              f"slow round trips {sum(r >= rto for r in rtts)}")
        assert lost > 0
        assert total >= lost * rto - EARLY
        assert total <= lost * rto + 25 * 0.01 + SLACK * 3
        assert sum(r >= rto - EARLY for r in rtts) >= 1

        # Bulk: data with losses still arrives intact and in order.
        data, pieces = random_pieces(random.Random(9), 300_000, 3_000)
        sender, errors = send_in_background(sock, pieces, pause=0.0005)
        received = recv_all(sock)
        sender.join(IO_TIMEOUT)
        assert not errors and received == data
        assert proxy.stats["lost_up"] > st["lost_up"]


def sink(conn):
    """Read an 8-byte length, then that many bytes; answer b'K'."""
    n = int.from_bytes(recv_exact(conn, 8), "big")
    recv_exact(conn, n)
    conn.sendall(b"K")


def source(conn):
    """Read an 8-byte length, then send that many bytes."""
    n = int.from_bytes(recv_exact(conn, 8), "big")
    conn.sendall(bytes(n))


@pytest.mark.parametrize("direction", ["up", "down"])
def test_bandwidth_limits_each_direction(direction):
    size, rate = 200_000, 1_000_000.0
    with TcpServer(sink if direction == "up" else source) as server, \
            LatencyProxy("127.0.0.1", server.port, bandwidth=rate) as proxy, \
            connect(proxy.port) as sock:
        t0 = time.monotonic()
        if direction == "up":
            sock.sendall(size.to_bytes(8, "big") + bytes(size))
            assert recv_exact(sock, 1) == b"K"
        else:
            sock.sendall(size.to_bytes(8, "big"))
            recv_exact(sock, size)
        elapsed = time.monotonic() - t0
    print(f"{direction}: {size} B at {rate:.0f} B/s took {elapsed:.3f} s")
    # The link carries at most `rate` bytes per second; the upper bound allows for the
    # last chunk's own serialisation and CI noise.
    assert elapsed >= size / rate - EARLY
    assert elapsed <= size / rate + 0.1 + SLACK


def test_queue_is_bounded_on_a_slow_link():
    size, bound = 400_000, 64 * 1024
    with TcpServer(sink) as server, \
            LatencyProxy("127.0.0.1", server.port, bandwidth=2_000_000.0,
                         max_queue_bytes=bound) as proxy, connect(proxy.port) as sock:
        sock.sendall(size.to_bytes(8, "big"))
        sender, errors = send_in_background(sock, [bytes(size)], shutdown=False)
        assert recv_exact(sock, 1) == b"K"
        sender.join(IO_TIMEOUT)
        st = proxy.stats
    assert not errors
    # The bound: the limit plus the one chunk read when the queue was just under it.
    assert bound <= st["peak_queued_up"] <= bound + proxy_mod.CHUNK_SIZE


def test_set_changes_the_delay_of_later_chunks(echo_server):
    with LatencyProxy("127.0.0.1", echo_server.port, delay=0.02) as proxy, \
            connect(proxy.port) as sock:
        before = median_rtt(sock, 3)
        proxy.set(delay=0.08)
        after = median_rtt(sock, 3)
        assert proxy.settings["delay"] == 0.08
        # Removing the cap and setting it again through set() works as documented.
        proxy.set(bandwidth=1e6)
        assert proxy.settings["bandwidth"] == 1e6
        proxy.set(bandwidth=None)
        assert proxy.settings["bandwidth"] is None
    print(f"rtt at delay 0.02: {before * 1e3:.1f} ms; after set(delay=0.08): "
          f"{after * 1e3:.1f} ms")
    assert 0.04 - EARLY <= before <= 0.04 + SLACK
    assert 0.16 - EARLY <= after <= 0.16 + SLACK


def test_set_from_another_thread_while_traffic_flows(echo_server):
    data, pieces = random_pieces(random.Random(1), 200_000, 2_000)
    with LatencyProxy("127.0.0.1", echo_server.port, seed=1) as proxy, \
            connect(proxy.port) as sock:
        sender, errors = send_in_background(sock, pieces, pause=0.0002)
        changer = threading.Thread(target=lambda: [
            proxy.set(delay=d, jitter=d / 2, loss=0.05, retransmit_timeout=0.01)
            for d in (0.001, 0.003, 0.0, 0.002)])
        changer.start()
        received = recv_all(sock)
        changer.join(IO_TIMEOUT)
        sender.join(IO_TIMEOUT)
    assert not errors and received == data


# -------------------------------------------------------------------- lifecycle

def test_stop_closes_everything(echo_server):
    proxy = LatencyProxy("127.0.0.1", echo_server.port).start()
    port = proxy.port
    assert proxy.address == ("127.0.0.1", port)
    clients = [connect(port) for _ in range(3)]
    for c in clients:
        rtt(c)  # each connection is established end to end
    assert proxy.stats["active"] == 3
    thread = proxy._thread
    t0 = time.monotonic()
    proxy.stop()
    assert time.monotonic() - t0 < 2.0
    assert not thread.is_alive()
    for c in clients:
        assert sees_closed(c)
        c.close()
    # The listener is gone: connecting is refused and a new listener can bind the port.
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.1", port), timeout=2).close()
    with socket.socket() as s:
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind(("127.0.0.1", port))
    # No proxy thread is left behind (every other test has stopped its proxy too).
    assert not [t for t in threading.enumerate() if t.name == "wmo-latency-proxy"]
    assert proxy.stats["active"] == 0
    proxy.stop()  # idempotent
    assert proxy.port == port  # still tells the port it used


def test_stop_with_bytes_in_flight_is_prompt(echo_server):
    proxy = LatencyProxy("127.0.0.1", echo_server.port, delay=1.0).start()
    sock = connect(proxy.port)
    sock.sendall(b"x" * 100_000)   # queued for a second in the proxy
    time.sleep(0.05)
    t0 = time.monotonic()
    proxy.stop()
    assert time.monotonic() - t0 < 1.0  # does not wait for the queued bytes
    assert sees_closed(sock)
    sock.close()
    proxy.stop()


def test_stop_from_another_thread_stops_a_proxy_on_a_foreign_loop(echo_server):
    # serve() on a loop the caller owns (here on a thread); stop() from another thread
    # must return once everything is closed, even though the loop stops right after.
    proxy = LatencyProxy("127.0.0.1", echo_server.port)
    listening = threading.Event()

    async def run():
        await proxy.start_async()
        listening.set()
        await proxy.serve()

    loop_thread = threading.Thread(target=lambda: asyncio.run(run()), daemon=True)
    loop_thread.start()
    assert listening.wait(IO_TIMEOUT)
    with connect(proxy.port) as sock:
        rtt(sock)
        proxy.stop()
        loop_thread.join(IO_TIMEOUT)
        assert not loop_thread.is_alive()
        assert sees_closed(sock)
    proxy.stop()


def test_restart_and_start_twice(echo_server):
    proxy = LatencyProxy("127.0.0.1", echo_server.port)
    with pytest.raises(RuntimeError):
        proxy.port  # not started yet
    with proxy:
        with pytest.raises(RuntimeError):
            proxy.start()
    with proxy, connect(proxy.port) as sock:  # a stopped proxy can start again
        rtt(sock)


def test_target_down_closes_the_client():
    with socket.socket() as s:  # a port nothing listens on
        s.bind(("127.0.0.1", 0))
        dead_port = s.getsockname()[1]
    with LatencyProxy("127.0.0.1", dead_port) as proxy:
        with connect(proxy.port) as sock:
            t0 = time.monotonic()
            assert sees_closed(sock, timeout=3.0)
            assert time.monotonic() - t0 < 3.0
        deadline = time.monotonic() + 2
        while proxy.stats["active"] and time.monotonic() < deadline:
            time.sleep(0.01)
        st = proxy.stats
    assert st["failed"] == 1 and st["active"] == 0


def test_listen_port_in_use_raises_from_start(echo_server):
    with pytest.raises(OSError):
        LatencyProxy("127.0.0.1", 1, listen_port=echo_server.port).start()


def test_asyncio_form(echo_server):
    async def run():
        proxy = await LatencyProxy("127.0.0.1", echo_server.port, delay=0.01).start_async()
        server_task = asyncio.ensure_future(proxy.serve())
        reader, writer = await asyncio.open_connection("127.0.0.1", proxy.port)
        t0 = time.monotonic()
        writer.write(b"hello")
        assert await asyncio.wait_for(reader.readexactly(5), IO_TIMEOUT) == b"hello"
        elapsed = time.monotonic() - t0
        await proxy.stop_async()
        await asyncio.wait_for(server_task, IO_TIMEOUT)
        assert await asyncio.wait_for(reader.read(), IO_TIMEOUT) == b""
        writer.close()
        await proxy.stop_async()  # idempotent
        return elapsed

    elapsed = asyncio.run(run())
    assert 0.02 - EARLY <= elapsed <= 0.02 + SLACK


# ------------------------------------------------------------------- validation

@pytest.mark.parametrize("kw, field, shown", [
    ({"delay": -0.01}, "delay", "-0.01"),
    ({"delay": math.nan}, "delay", "nan"),
    ({"delay": math.inf}, "delay", "inf"),
    ({"delay": "20ms"}, "delay", "'20ms'"),
    ({"jitter": -1}, "jitter", "-1"),
    ({"jitter": math.nan}, "jitter", "nan"),
    ({"loss": 1.0}, "loss", "1.0"),
    ({"loss": -0.1}, "loss", "-0.1"),
    ({"loss": math.nan}, "loss", "nan"),
    ({"bandwidth": 0}, "bandwidth", "0"),
    ({"bandwidth": -5.0}, "bandwidth", "-5.0"),
    ({"bandwidth": math.nan}, "bandwidth", "nan"),
    ({"retransmit_timeout": -0.2}, "retransmit_timeout", "-0.2"),
    ({"listen_port": -1}, "listen_port", "-1"),
    ({"listen_port": 65536}, "listen_port", "65536"),
    ({"target_port": 0}, "target_port", "0"),
    ({"target_port": "80"}, "target_port", "'80'"),
    ({"target_port": 70000}, "target_port", "70000"),
    ({"max_queue_bytes": 0}, "max_queue_bytes", "0"),
    ({"seed": 1.5}, "seed", "1.5"),
])
def test_constructor_validation(kw, field, shown):
    args = {"target_host": "127.0.0.1", "target_port": 8765}
    args.update(kw)
    host, port = args.pop("target_host"), args.pop("target_port")
    with pytest.raises(ValueError) as info:
        LatencyProxy(host, port, **args)
    assert field in str(info.value) and shown in str(info.value)


def test_set_validation_changes_nothing_on_error():
    proxy = LatencyProxy("127.0.0.1", 8765, delay=0.01)
    with pytest.raises(ValueError, match=r"loss.*1\.5"):
        proxy.set(delay=0.5, loss=1.5)
    with pytest.raises(ValueError, match="bandwidth"):
        proxy.set(bandwidth=0)
    with pytest.raises(ValueError, match="jitter"):
        proxy.set(jitter=math.nan)
    assert proxy.settings["delay"] == 0.01 and proxy.settings["loss"] == 0.0


def test_presets_are_valid():
    assert {"lan", "wan20", "wan40", "wan100", "lossy", "mobile"} <= set(PRESETS)
    for preset in PRESETS.values():
        LatencyProxy("127.0.0.1", 8765, **preset)  # every preset is a valid setting
    assert PRESETS["wan20"]["delay"] == 0.02 and PRESETS["wan20"]["jitter"] == 0.002
    assert PRESETS["mobile"] == {"delay": 0.1, "jitter": 0.02, "loss": 0.01,
                                 "bandwidth": 1e6}


@pytest.mark.parametrize("text, seconds", [
    ("20ms", 0.02), ("0.02", 0.02), ("0.02s", 0.02), ("0", 0.0), ("500us", 0.0005),
    ("1e-3", 0.001), (" 5 ms ", 0.005)])
def test_parse_duration(text, seconds):
    assert parse_duration(text) == pytest.approx(seconds)


@pytest.mark.parametrize("text, rate", [
    ("1MB/s", 1e6), ("8Mbit/s", 1e6), ("125000", 125000.0), ("8mbit", 1e6),
    ("500KB/s", 5e5), ("1MiB/s", 1048576.0), ("64kbps", 8000.0), ("unlimited", None)])
def test_parse_bandwidth(text, rate):
    assert parse_bandwidth(text) == rate


@pytest.mark.parametrize("option, value", [
    ("--delay", "abc"), ("--delay", "-5ms"), ("--jitter", "2 fortnights"),
    ("--loss", "1.5"), ("--loss", "lots"), ("--bandwidth", "0"), ("--bandwidth", "1Mb/s"),
    ("--bandwidth", "fast"), ("--preset", "moon"), ("--seed", "x"),
    ("--listen", "127.0.0.1:99999"), ("--retransmit-timeout", "soon")])
def test_cli_bad_value_exits_2_naming_option_and_value(capsys, option, value):
    # OPTION=VALUE: argparse would read a separate "-5ms" as an option of its own.
    assert main(["--target", "127.0.0.1:8765", f"{option}={value}"]) == 2
    err = capsys.readouterr().err
    assert option in err and value in err


def test_cli_bad_target(capsys):
    assert main(["--target", "nohost:"]) == 2
    err = capsys.readouterr().err
    assert "--target" in err and "nohost:" in err
    assert main([]) == 2  # --target is required
    assert "--target" in capsys.readouterr().err


def test_cli_help(capsys):
    assert main(["--help"]) == 0
    out = capsys.readouterr().out
    for word in ("--target", "--delay", "--bandwidth", "--preset", "wan20", "mobile"):
        assert word in out


def test_cli_runs_until_sigterm(echo_server):
    env = dict(os.environ)
    src = os.path.join(os.path.dirname(__file__), "..", "..", "python")
    env["PYTHONPATH"] = os.path.abspath(src) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.Popen(
        [sys.executable, "-m", "wmo.remote.proxy", "--target",
         f"127.0.0.1:{echo_server.port}", "--preset", "wan20", "--delay", "10ms",
         "--seed", "1"],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env, text=True)
    try:
        line = _readline_with_timeout(proc.stdout, IO_TIMEOUT)
        assert line.startswith("listening on 127.0.0.1:"), line
        assert "delay 10 ms" in line and "jitter 2 ms" in line  # option overrides preset
        port = int(line.split()[2].rsplit(":", 1)[1])
        with connect(port) as sock:
            assert rtt(sock) >= 0.02 - EARLY
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(IO_TIMEOUT) == 0
        assert "stats" in proc.stderr.read()
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        proc.stdout.close()
        proc.stderr.close()


def _readline_with_timeout(stream, timeout):
    result = []
    t = threading.Thread(target=lambda: result.append(stream.readline()), daemon=True)
    t.start()
    t.join(timeout)
    assert result, "the CLI printed nothing"
    return result[0]

"""A latency-injecting TCP proxy for loopback experiments (standard library only).

The kernel's ``netem`` module is not available on every machine, so experiments that put
network latency between the physics server and a client run the client's connection
through this proxy instead::

    python -m wmo.remote.proxy --target 127.0.0.1:8765 --listen 127.0.0.1:9765 --preset wan20

    with LatencyProxy("127.0.0.1", 8765, **PRESETS["wan20"]) as proxy:
        connect(f"ws://127.0.0.1:{proxy.port}", ...)

The model
---------
*What is delayed.* Bytes are read from each side as they arrive, in *chunks* (one
``read()`` of at most 64 KiB; on loopback one ``send()`` by the sender, for example one
WebSocket frame of a few KB, usually arrives as one chunk). Each chunk is time-stamped
when read and written to the other side at its *due time*. Both directions are delayed
independently with the same settings: ``delay`` is the **one-way** delay, so a round trip
grows by ``2 * delay`` (the ``wan20`` preset adds 40 ms to the round-trip time). The end
of the stream (a half-close, FIN) travels through the same pipe: it is passed on after
the bytes before it and no earlier than ``delay`` after it was seen.

*Due time of a chunk* of ``n`` bytes read at time ``t``:

1. bandwidth (serialisation and queueing): the direction's emulated link is busy until
   the previous chunk has been sent; this chunk starts at ``max(t, link_free)`` and takes
   ``n / bandwidth`` seconds. Each proxied connection has its own link per direction (as
   if every client had its own access link); ``bandwidth=None`` means no serialisation
   delay at all. A chunk is released whole when its last byte has crossed the link
   (store and forward).
2. propagation: ``+ delay + U * jitter`` where ``U`` is uniform in [0, 1), so the added
   delay of a chunk is uniform in ``[delay, delay + jitter)``; its mean is
   ``delay + jitter / 2``. (netem's ``delay 20ms 2ms`` is uniform in ``[18, 22]`` ms
   instead; this proxy never goes below ``delay``.)
3. loss: with probability ``loss`` the chunk is "lost". TCP cannot lose bytes (the
   receiving application never sees a gap), so a loss is emulated the way TCP repairs
   it: the chunk arrives late by ``max(retransmit_timeout, 2 * delay)``, the time a
   sender needs before it can notice the loss (the retransmission timeout, at least one
   round trip) and retransmit. Everything behind it in the same direction waits for it
   (head-of-line blocking, as a TCP receiver holds out-of-order segments back until the
   gap is filled). The retransmission does not occupy the emulated link a second time.
   Loss is drawn per chunk, not per packet: on loopback (MTU 64 KiB) netem also drops
   whole segments of up to 64 KiB, so the two agree roughly.
4. ordering: the due time is raised to the due time of the previous chunk of the same
   direction, so bytes are **never reordered** and jitter never makes a later chunk
   overtake an earlier one. A consequence: when chunks are closer together than the
   jitter, later chunks inherit part of an earlier chunk's extra delay, as in a real
   FIFO queue.

Settings changed with :meth:`LatencyProxy.set` apply to chunks read after the call.

*Not modelled.* The TCP handshake is not delayed (the kernel completes it before the
proxy accepts), so a client's ``connect()`` returns about one round trip sooner than over
a real link; the first bytes (for example a WebSocket upgrade request) are delayed as
usual. TCP's congestion control is not emulated: a loss delays a chunk but does not slow
the sender down.

*Memory bound.* Each direction of each connection holds at most ``max_queue_bytes``
(default 4 MiB) plus one chunk (64 KiB) of bytes waiting for their due time: when the
queue is full the proxy stops reading from that side, the kernel's socket buffers fill up
and TCP flow control blocks the sender. asyncio adds at most about 128 KiB of read buffer
and 64 KiB of write buffer per direction. A full queue also limits throughput to about
``max_queue_bytes / delay`` (like a TCP window), 40 MB/s for 4 MiB at 100 ms, far above a
60 Hz stream of a few KB per frame.

*Stats.* :attr:`LatencyProxy.stats` counts, per direction ("up" = client to target,
"down" = target to client), the bytes and chunks delivered, the chunks lost (delivered
late), and the largest queue seen.

The same effect with Linux netem
--------------------------------
Where the ``sch_netem`` module exists (``modprobe sch_netem``), the kernel can do this
for all loopback traffic, as root::

    tc qdisc add dev lo root netem delay 20ms 2ms loss 1% rate 8mbit
    tc qdisc change dev lo root netem delay 40ms      # change it
    tc qdisc del dev lo root                          # remove it

netem on ``lo`` delays every packet sent over loopback, so **both directions** are
delayed (the round trip grows by twice the delay, as with this proxy), and every
loopback connection on the machine is affected, not only the experiment's. Its ``rate``
is shared by both directions and all connections, its loss is per packet, and with jitter
it may reorder packets (TCP then puts them back in order). ``rate 8mbit`` is 1 MB/s.
"""
from __future__ import annotations

import argparse
import asyncio
import itertools
import logging
import math
import numbers
import random
import re
import signal
import sys
import threading
from dataclasses import dataclass, replace

__all__ = ["LatencyProxy", "PRESETS", "main", "parse_duration", "parse_bandwidth"]

log = logging.getLogger(__name__)

#: Largest read from a socket, bytes: the largest chunk the proxy delays as one unit.
CHUNK_SIZE = 64 * 1024
#: Default bound on the bytes waiting in one direction of one connection.
DEFAULT_MAX_QUEUE_BYTES = 4 * 1024 * 1024
#: Seconds to wait for the target to accept a connection before giving up.
DEFAULT_CONNECT_TIMEOUT = 5.0
#: Seconds a graceful close may take (flushing to a peer that does not read) before it
#: becomes an abort.
_CLOSE_TIMEOUT = 2.0

#: Named settings for :class:`LatencyProxy` (``LatencyProxy(host, port, **PRESETS[name])``)
#: and the CLI's ``--preset``. Delays and jitter are one-way, in seconds (the round trip
#: grows by twice the delay); loss is a probability per chunk; bandwidth is bytes per
#: second per direction, ``None`` for unlimited.
#:
#: ========  =======  =======  =====  ==================
#: name      delay    jitter   loss   bandwidth
#: ========  =======  =======  =====  ==================
#: lan       0 ms     0 ms     0      unlimited
#: wan20     20 ms    2 ms     0      unlimited
#: wan40     40 ms    4 ms     0      unlimited
#: wan100    100 ms   10 ms    0      unlimited
#: lossy     40 ms    0 ms     1 %    unlimited
#: mobile    100 ms   20 ms    1 %    1 MB/s (8 Mbit/s)
#: ========  =======  =======  =====  ==================
PRESETS: dict[str, dict] = {
    "lan": {"delay": 0.0, "jitter": 0.0, "loss": 0.0, "bandwidth": None},
    "wan20": {"delay": 0.020, "jitter": 0.002, "loss": 0.0, "bandwidth": None},
    "wan40": {"delay": 0.040, "jitter": 0.004, "loss": 0.0, "bandwidth": None},
    "wan100": {"delay": 0.100, "jitter": 0.010, "loss": 0.0, "bandwidth": None},
    "lossy": {"delay": 0.040, "jitter": 0.0, "loss": 0.01, "bandwidth": None},
    "mobile": {"delay": 0.100, "jitter": 0.020, "loss": 0.01, "bandwidth": 1_000_000.0},
}

# Marks "argument not given" where None is a meaningful value (bandwidth=None: unlimited).
_UNSET = object()


# ----------------------------------------------------------------------------- settings

def _check_seconds(name: str, value) -> float:
    """`value` as a float number of seconds, finite and >= 0, else ValueError naming `name`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number of seconds, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v < 0.0:
        raise ValueError(f"{name} must be a finite number of seconds >= 0, got {value!r}")
    return v


def _check_loss(value) -> float:
    """`value` as a loss probability in [0, 1), else ValueError."""
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"loss must be a probability in [0, 1), got {value!r}")
    v = float(value)
    if not (0.0 <= v < 1.0):  # also refuses NaN
        raise ValueError(f"loss must be a probability in [0, 1), got {value!r}")
    return v


def _check_bandwidth(value) -> float | None:
    """`value` as bytes per second (finite, > 0) or None for unlimited, else ValueError."""
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"bandwidth must be bytes per second or None, got {value!r}")
    v = float(value)
    if not math.isfinite(v) or v <= 0.0:
        raise ValueError(f"bandwidth must be a finite number of bytes per second > 0 "
                         f"(None for unlimited), got {value!r}")
    return v


def _check_port(name: str, value, lowest: int) -> int:
    """`value` as a TCP port in [lowest, 65535], else ValueError naming `name`."""
    if isinstance(value, bool) or not isinstance(value, numbers.Integral) \
            or not (lowest <= int(value) <= 65535):
        raise ValueError(f"{name} must be an integer port in [{lowest}, 65535], got {value!r}")
    return int(value)


def _check_host(name: str, value) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError(f"{name} must be a non-empty host name or address, got {value!r}")
    return value


@dataclass(frozen=True)
class _Settings:
    """One consistent set of link settings. Immutable: set() swaps the whole object, so
    the proxy's thread always sees either the old or the new settings, never a mix."""
    delay: float
    jitter: float
    loss: float
    bandwidth: float | None
    retransmit_timeout: float


class _Link:
    """The emulated link of one direction of one connection: turns the arrival time and
    size of each chunk into the time it is released (see the module docstring)."""

    def __init__(self, rng: random.Random):
        self._rng = rng
        self._link_free_at = -math.inf   # when the link has finished sending the previous chunk
        self._last_due = -math.inf       # due time of the previous chunk (release order)

    def schedule(self, now: float, size: int, s: _Settings) -> tuple[float, bool]:
        """(due time, lost) of a chunk of `size` bytes read at `now` (loop time, seconds)."""
        # Two draws per chunk whatever the settings, so a seed gives the same loss
        # pattern with or without jitter.
        u_jitter = self._rng.random()
        u_loss = self._rng.random()
        if s.bandwidth is None:
            sent = now
        else:
            sent = max(now, self._link_free_at) + size / s.bandwidth
        self._link_free_at = sent
        due = sent + s.delay + u_jitter * s.jitter
        lost = u_loss < s.loss
        if lost:
            # A sender notices a loss after its retransmission timeout, which is at least
            # one round trip (2 * delay here), then the retransmission crosses the link.
            due += max(s.retransmit_timeout, 2.0 * s.delay)
        due = max(due, self._last_due)  # never overtake the previous chunk
        self._last_due = due
        return due, lost

    def schedule_eof(self, now: float, s: _Settings) -> float:
        """Due time of the end of the stream seen at `now`: after everything before it,
        and no sooner than one delay later (the FIN crosses the link too)."""
        due = max(now, self._link_free_at) + s.delay
        due = max(due, self._last_due)
        self._last_due = due
        return due


class _Pipe:
    """One direction of one proxied connection: a reader task that time-stamps chunks
    and queues them, and a writer task that releases them at their due times."""

    def __init__(self, proxy: LatencyProxy, direction: str, reader: asyncio.StreamReader,
                 writer: asyncio.StreamWriter, rng: random.Random):
        self._proxy = proxy
        self._direction = direction  # "up" (client -> target) or "down" (target -> client)
        self._reader = reader
        self._writer = writer
        self._link = _Link(rng)
        self._queue: asyncio.Queue = asyncio.Queue()  # (due, bytes or None for EOF)
        self._queued = 0                               # bytes in _queue
        self._space = asyncio.Event()                  # set when the writer frees queue space

    async def read_loop(self) -> None:
        loop = asyncio.get_running_loop()
        limit = self._proxy._max_queue_bytes
        while True:
            # The memory bound: stop reading while the queue is full, so TCP flow
            # control pushes back on the sender instead of the queue growing.
            while self._queued >= limit:
                self._space.clear()
                await self._space.wait()
            data = await self._reader.read(CHUNK_SIZE)
            now = loop.time()
            settings = self._proxy._settings
            if not data:
                self._queue.put_nowait((self._link.schedule_eof(now, settings), None))
                return
            due, lost = self._link.schedule(now, len(data), settings)
            self._queued += len(data)
            self._proxy._count(self._direction, lost=int(lost), queued=self._queued)
            self._queue.put_nowait((due, data))

    async def write_loop(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            due, data = await self._queue.get()
            wait = due - loop.time()
            if wait > 0:
                await asyncio.sleep(wait)
            if data is None:
                # Pass the half-close on; the transport sends the FIN after its buffer.
                if self._writer.can_write_eof():
                    self._writer.write_eof()
                return
            # Counted before the write, so a peer that has the bytes sees them counted.
            self._proxy._count(self._direction, nbytes=len(data), chunks=1)
            self._writer.write(data)
            self._queued -= len(data)
            self._space.set()
            await self._writer.drain()


async def _close_writer(writer: asyncio.StreamWriter | None, abort: bool) -> None:
    """Close a stream: abort (drop unsent bytes, reset the peer) or close gracefully
    (flush first), turning a graceful close that takes too long into an abort."""
    if writer is None:
        return
    transport = writer.transport
    if abort:
        transport.abort()
    else:
        writer.close()
    try:
        await asyncio.wait_for(writer.wait_closed(), _CLOSE_TIMEOUT)
    except asyncio.TimeoutError:
        transport.abort()
    except (OSError, asyncio.CancelledError):
        # The peer may already have reset the connection; a cancelled wait (shutdown)
        # still leaves the transport closed or aborted.
        transport.abort()


# ------------------------------------------------------------------------------- proxy

class LatencyProxy:
    """Forwards TCP connections from (listen_host, listen_port) to (target_host,
    target_port), delaying each direction's bytes (the model is in the module docstring).

    Parameters (durations in seconds, rates in bytes per second):

    target_host, target_port
        Where each accepted connection is forwarded (a new connection per client).
    listen_host, listen_port
        Where the proxy listens; port 0 picks a free port (read it from :attr:`port`).
    delay
        One-way added delay, applied in each direction (the round trip grows by
        ``2 * delay``).
    jitter
        Each chunk's delay is ``delay`` plus a uniform random extra in ``[0, jitter)``;
        bytes are never reordered.
    loss
        Probability in [0, 1) that a chunk is "lost": it is delivered late by
        ``max(retransmit_timeout, 2 * delay)`` and holds back what follows it.
    bandwidth
        Bytes per second per direction and connection, ``None`` for unlimited: a chunk
        of ``n`` bytes occupies the link for ``n / bandwidth`` seconds.
    retransmit_timeout
        Lower bound of the extra delay of a lost chunk (Linux's minimum RTO is 0.2 s).
    seed
        Seed of the jitter and loss draws (each connection and direction draws from its
        own generator seeded from it), ``None`` for fresh randomness. Which bytes form a
        chunk still depends on timing, so a seed fixes the draws, not the bytes they hit.
    max_queue_bytes
        Bound on the bytes waiting in one direction of one connection (see the module
        docstring); reading from that side pauses while it is reached.
    connect_timeout
        Seconds to wait for the target to accept a connection; a client whose target
        cannot be reached is disconnected.

    Run it on its own thread with :meth:`start`/:meth:`stop` (or ``with``), or inside a
    running asyncio loop with :meth:`start_async`/:meth:`stop_async` or :meth:`serve`.
    Raises ValueError naming the field for a negative or NaN delay, jitter or
    retransmit_timeout, a loss outside [0, 1), a bandwidth <= 0, or a bad port.
    """

    def __init__(self, target_host: str, target_port: int, *, listen_host: str = "127.0.0.1",
                 listen_port: int = 0, delay: float = 0.0, jitter: float = 0.0,
                 loss: float = 0.0, bandwidth: float | None = None,
                 retransmit_timeout: float = 0.2, seed: int | None = None,
                 max_queue_bytes: int = DEFAULT_MAX_QUEUE_BYTES,
                 connect_timeout: float = DEFAULT_CONNECT_TIMEOUT):
        self._target_host = _check_host("target_host", target_host)
        self._target_port = _check_port("target_port", target_port, 1)
        self._listen_host = _check_host("listen_host", listen_host)
        self._listen_port = _check_port("listen_port", listen_port, 0)
        self._settings = _Settings(
            delay=_check_seconds("delay", delay), jitter=_check_seconds("jitter", jitter),
            loss=_check_loss(loss), bandwidth=_check_bandwidth(bandwidth),
            retransmit_timeout=_check_seconds("retransmit_timeout", retransmit_timeout))
        if isinstance(max_queue_bytes, bool) or not isinstance(max_queue_bytes, numbers.Integral) \
                or max_queue_bytes < 1:
            raise ValueError(f"max_queue_bytes must be an integer >= 1, got {max_queue_bytes!r}")
        self._max_queue_bytes = int(max_queue_bytes)
        ct = _check_seconds("connect_timeout", connect_timeout)
        if ct <= 0:
            raise ValueError(f"connect_timeout must be > 0 seconds, got {connect_timeout!r}")
        self._connect_timeout = ct
        if seed is not None and (isinstance(seed, bool) or not isinstance(seed, numbers.Integral)):
            raise ValueError(f"seed must be an integer or None, got {seed!r}")
        self._seed = seed

        self._settings_lock = threading.Lock()   # serialises set()
        self._stats_lock = threading.Lock()      # guards _stats (written by the loop thread)
        self._stats = {
            "connections": 0, "active": 0, "failed": 0,
            "bytes_up": 0, "bytes_down": 0, "chunks_up": 0, "chunks_down": 0,
            "lost_up": 0, "lost_down": 0, "peak_queued_up": 0, "peak_queued_down": 0,
        }
        self._state_lock = threading.Lock()      # serialises start()/stop()
        self._conn_numbers = itertools.count()
        self._address: tuple[str, int] | None = None
        # Loop-side state (touched only from the proxy's event loop):
        self._loop: asyncio.AbstractEventLoop | None = None
        self._server: asyncio.AbstractServer | None = None
        self._stop_event: asyncio.Event | None = None   # set to ask serve() to return
        self._shutdown_task: asyncio.Future | None = None  # the one task closing everything
        self._conn_tasks: set = set()
        self._closing = False
        # Set (from the loop) once a shutdown has finished: lets another thread wait for
        # it without depending on the loop running any longer.
        self._stopped = threading.Event()
        # Thread mode:
        self._thread: threading.Thread | None = None
        self._start_error: BaseException | None = None

    # -- properties

    @property
    def port(self) -> int:
        """The port the proxy listens on (the one picked when listen_port was 0); after
        stop(), the port it listened on. RuntimeError before the first start."""
        return self.address[1]

    @property
    def address(self) -> tuple[str, int]:
        """(host, port) the proxy listens on, as for :attr:`port`."""
        if self._address is None:
            raise RuntimeError("the proxy has not been started")
        return self._address

    @property
    def target(self) -> tuple[str, int]:
        """(host, port) connections are forwarded to."""
        return (self._target_host, self._target_port)

    @property
    def settings(self) -> dict:
        """The current delay, jitter, retransmit_timeout (seconds), loss (probability)
        and bandwidth (bytes per second or None)."""
        s = self._settings
        return {"delay": s.delay, "jitter": s.jitter, "loss": s.loss,
                "bandwidth": s.bandwidth, "retransmit_timeout": s.retransmit_timeout}

    @property
    def stats(self) -> dict:
        """A snapshot of the counters (safe to read from any thread):

        connections / active / failed
            client connections accepted in total / open now / closed because the target
            could not be reached.
        bytes_up, bytes_down / chunks_up, chunks_down
            bytes / chunks delivered client -> target ("up") and target -> client ("down").
        lost_up, lost_down
            chunks that were "lost" (and delivered late), counted when read.
        peak_queued_up, peak_queued_down
            the most bytes seen waiting in one connection's queue, bytes.
        """
        with self._stats_lock:
            return dict(self._stats)

    def _count(self, direction: str, *, nbytes: int = 0, chunks: int = 0, lost: int = 0,
               queued: int = 0) -> None:
        with self._stats_lock:
            st = self._stats
            st["bytes_" + direction] += nbytes
            st["chunks_" + direction] += chunks
            st["lost_" + direction] += lost
            key = "peak_queued_" + direction
            if queued > st[key]:
                st[key] = queued

    def _count_conn(self, **deltas: int) -> None:
        with self._stats_lock:
            for k, d in deltas.items():
                self._stats[k] += d

    # -- settings

    def set(self, *, delay=None, jitter=None, loss=None, bandwidth=_UNSET,
            retransmit_timeout=None) -> None:
        """Change settings while running (or before start), from any thread. Arguments
        left out (None; for bandwidth, not given) keep their value; ``bandwidth=None``
        removes the cap. Applies to chunks read after the call; chunks already queued
        keep their due times, and later chunks still never overtake them. Everything is
        validated before anything changes (ValueError as for the constructor)."""
        changes = {}
        if delay is not None:
            changes["delay"] = _check_seconds("delay", delay)
        if jitter is not None:
            changes["jitter"] = _check_seconds("jitter", jitter)
        if loss is not None:
            changes["loss"] = _check_loss(loss)
        if bandwidth is not _UNSET:
            changes["bandwidth"] = _check_bandwidth(bandwidth)
        if retransmit_timeout is not None:
            changes["retransmit_timeout"] = _check_seconds("retransmit_timeout",
                                                           retransmit_timeout)
        with self._settings_lock:
            # One reference assignment: the loop thread sees old or new, never a mix.
            self._settings = replace(self._settings, **changes)

    # -- thread mode

    def start(self) -> LatencyProxy:
        """Start the proxy on its own daemon thread with its own asyncio loop; returns
        self once it is listening. Raises OSError if the listen address cannot be bound,
        RuntimeError if it is already running."""
        with self._state_lock:
            if self._thread is not None or self._server is not None:
                raise RuntimeError("the proxy is already running")
            ready = threading.Event()
            self._start_error = None
            thread = threading.Thread(target=self._thread_main, args=(ready,),
                                      name="wmo-latency-proxy", daemon=True)
            thread.start()
            ready.wait()
            if self._start_error is not None:
                thread.join()
                err, self._start_error = self._start_error, None
                raise err
            self._thread = thread
        return self

    def stop(self) -> None:
        """Close the listener and every connection (clients see EOF or a reset; queued
        bytes are dropped) and join the thread. Idempotent; safe from any thread but the
        proxy's own. For a proxy started with :meth:`start_async`, called from another
        thread, it stops it on its loop."""
        with self._state_lock:
            thread, loop = self._thread, self._loop
            if thread is None:
                if loop is not None and self._server is not None:
                    self._stop_foreign_loop(loop)
                return
            if thread is threading.current_thread():
                raise RuntimeError("stop() called from the proxy's own thread")
            try:
                loop.call_soon_threadsafe(self._stop_event.set)
            except RuntimeError:
                pass  # the loop has already closed (it failed); the thread is ending anyway
            thread.join()
            self._thread = None

    def _stop_foreign_loop(self, loop: asyncio.AbstractEventLoop) -> None:
        try:
            running = asyncio.get_running_loop()
        except RuntimeError:
            running = None
        if running is loop:
            raise RuntimeError("this proxy runs on the current loop: use await stop_async()")

        def request_stop():
            self._stop_event.set()
            self._begin_shutdown()

        # Wait on a threading.Event, not on a future of the loop: once serve() returns,
        # the loop's owner may stop running it before such a future would be resolved.
        loop.call_soon_threadsafe(request_stop)
        if not self._stopped.wait(4 * _CLOSE_TIMEOUT):
            raise RuntimeError("the proxy's event loop did not stop it (is the loop running?)")

    def _thread_main(self, ready: threading.Event) -> None:
        loop = asyncio.new_event_loop()
        try:
            loop.run_until_complete(self._thread_serve(ready))
        except BaseException as exc:  # noqa: BLE001 - reported to start() or logged
            if not ready.is_set():
                self._start_error = exc
            else:
                log.exception("latency proxy stopped by an error")
        finally:
            # Anything still pending (a connection accepted during shutdown) is cancelled
            # so no task or socket outlives the loop.
            pending = asyncio.all_tasks(loop)
            for task in pending:
                task.cancel()
            if pending:
                loop.run_until_complete(asyncio.gather(*pending, return_exceptions=True))
            loop.run_until_complete(loop.shutdown_asyncgens())
            loop.close()
            ready.set()

    async def _thread_serve(self, ready: threading.Event) -> None:
        await self.start_async()
        ready.set()
        try:
            await self._stop_event.wait()
        finally:
            await self._shutdown()

    def __enter__(self) -> LatencyProxy:
        return self.start()

    def __exit__(self, *exc_info) -> None:
        self.stop()

    # -- asyncio mode

    async def start_async(self) -> LatencyProxy:
        """Start listening on the running asyncio loop; returns self. Stop it with
        :meth:`stop_async` (or run :meth:`serve`)."""
        if self._server is not None:
            raise RuntimeError("the proxy is already running")
        self._loop = asyncio.get_running_loop()
        self._stop_event = asyncio.Event()
        self._shutdown_task = None
        self._closing = False
        self._stopped.clear()
        self._server = await asyncio.start_server(self._handle_client, self._listen_host,
                                                  self._listen_port)
        self._address = tuple(self._server.sockets[0].getsockname()[:2])
        log.debug("latency proxy listening on %s:%d", *self._address)
        return self

    async def stop_async(self) -> None:
        """Close the listener and all connections; idempotent."""
        if self._stop_event is not None:
            self._stop_event.set()
        await self._shutdown()

    async def serve(self) -> None:
        """Run on the current loop until :meth:`stop_async` (or :meth:`stop` from another
        thread) is called or the task is cancelled; starts listening first if needed."""
        if self._server is None:
            await self.start_async()
        try:
            await self._stop_event.wait()
        finally:
            await self._shutdown()

    def _begin_shutdown(self) -> asyncio.Future | None:
        """Start closing everything, once; the task doing it (None if not running)."""
        if self._shutdown_task is None:
            if self._server is None:
                return None
            self._shutdown_task = asyncio.ensure_future(self._close_all())
        return self._shutdown_task

    async def _shutdown(self) -> None:
        """Close everything and return when it is closed, however many callers (serve(),
        stop_async(), stop()) ask at once."""
        task = self._begin_shutdown()
        if task is not None:
            # shield: a caller cancelled while waiting does not interrupt the closing.
            await asyncio.shield(task)

    async def _close_all(self) -> None:
        try:
            await self._close_server_and_connections()
        finally:
            self._stopped.set()

    async def _close_server_and_connections(self) -> None:
        server, self._server = self._server, None
        self._closing = True
        server.close()
        if hasattr(server, "abort_clients"):  # Python 3.13+: also connections not yet handled
            server.abort_clients()
        tasks = list(self._conn_tasks)
        for task in tasks:
            task.cancel()  # each handler aborts its two sockets in its finally
        if tasks:
            await asyncio.wait(tasks, timeout=_CLOSE_TIMEOUT)
        try:
            await asyncio.wait_for(server.wait_closed(), _CLOSE_TIMEOUT)
        except asyncio.TimeoutError:
            log.warning("latency proxy: listener did not close within %.0f s", _CLOSE_TIMEOUT)

    # -- one connection

    async def _handle_client(self, client_reader: asyncio.StreamReader,
                             client_writer: asyncio.StreamWriter) -> None:
        try:
            await self._proxy_connection(client_reader, client_writer)
        except asyncio.CancelledError:
            # Cancelled by stop(), after the sockets were closed. Ending normally matters:
            # Python 3.11's start_server reports a cancelled handler as an error.
            pass

    async def _proxy_connection(self, client_reader: asyncio.StreamReader,
                                client_writer: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        self._conn_tasks.add(task)
        self._count_conn(connections=1, active=1)
        number = next(self._conn_numbers)
        target_writer = None
        abort = True  # unless both directions finish normally
        try:
            if self._closing:
                return
            try:
                target_reader, target_writer = await asyncio.wait_for(
                    asyncio.open_connection(self._target_host, self._target_port),
                    self._connect_timeout)
            except (OSError, asyncio.TimeoutError) as exc:
                # Close the client's connection (gracefully: it has nothing queued) so it
                # sees the end of the stream rather than hanging.
                self._count_conn(failed=1)
                log.warning("latency proxy: cannot connect to %s:%d: %s",
                            self._target_host, self._target_port, exc or "timed out")
                abort = False
                return
            pipes = [
                _Pipe(self, "up", client_reader, target_writer, self._rng(number, "up")),
                _Pipe(self, "down", target_reader, client_writer, self._rng(number, "down")),
            ]
            tasks = [asyncio.ensure_future(coro) for p in pipes
                     for coro in (p.read_loop(), p.write_loop())]
            try:
                done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_EXCEPTION)
            finally:
                for t in tasks:
                    t.cancel()
                await asyncio.gather(*tasks, return_exceptions=True)
            errors = [t.exception() for t in done if not t.cancelled() and t.exception()]
            if errors:
                # A reset or a broken pipe on one side: reset the other side too, as a
                # broken path would.
                log.debug("latency proxy: connection %d ended by %r", number, errors[0])
            else:
                abort = False
        finally:
            await _close_writer(client_writer, abort)
            await _close_writer(target_writer, abort)
            self._conn_tasks.discard(task)
            self._count_conn(active=-1)

    def _rng(self, number: int, direction: str) -> random.Random:
        if self._seed is None:
            return random.Random()
        # A string seed is hashed deterministically (SHA-512), unlike hash() of a tuple.
        return random.Random(f"{self._seed}/{number}/{direction}")


# --------------------------------------------------------------------------------- CLI

_DURATION_RE = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)(?:[eE]([-+]?\d+))?\s*(us|µs|ms|s)?\s*$")
_DURATION_UNITS = {None: 1.0, "s": 1.0, "ms": 1e-3, "us": 1e-6, "µs": 1e-6}
_BANDWIDTH_RE = re.compile(r"^\s*(\d+(?:\.\d*)?|\.\d+)(?:[eE]([-+]?\d+))?\s*([A-Za-z]*)(/s)?\s*$")
_BYTE_PREFIXES = {"": 1.0, "k": 1e3, "m": 1e6, "g": 1e9, "ki": 1024.0, "mi": 1024.0 ** 2,
                  "gi": 1024.0 ** 3}
_BIT_UNITS = {"bit": 1.0, "kbit": 1e3, "mbit": 1e6, "gbit": 1e9,
              "bps": 1.0, "kbps": 1e3, "mbps": 1e6, "gbps": 1e9}


def _number(mantissa: str, exponent: str | None) -> float:
    return float(mantissa + ("e" + exponent if exponent else ""))


def parse_duration(text: str) -> float:
    """Seconds from '20ms', '0.02s', '0.02' (seconds) or '500us'; ValueError otherwise
    (negative values are refused)."""
    m = _DURATION_RE.match(text)
    if not m:
        raise ValueError(f"invalid duration {text!r} (expected e.g. 20ms, 0.02s or 0.02)")
    value = _number(m.group(1), m.group(2)) * _DURATION_UNITS[m.group(3)]
    if not math.isfinite(value):
        raise ValueError(f"invalid duration {text!r}: not finite")
    return value


def parse_bandwidth(text: str) -> float | None:
    """Bytes per second from '125000' (bytes/s), '1MB/s', '500KB/s', '2MiB/s' (bytes,
    decimal or binary prefixes), '8Mbit/s' or '8Mbps' (bits); 'unlimited' or 'none' give
    None. A bare lower-case 'b' ('1Mb/s') is refused as ambiguous. ValueError otherwise
    (also for 0)."""
    if text.strip().lower() in ("unlimited", "none"):
        return None
    m = _BANDWIDTH_RE.match(text)
    if not m:
        raise ValueError(f"invalid bandwidth {text!r} (expected e.g. 1MB/s, 8Mbit/s or 125000)")
    value = _number(m.group(1), m.group(2))
    unit = m.group(3)
    if unit.lower() in _BIT_UNITS:
        rate = value * _BIT_UNITS[unit.lower()] / 8.0
    elif unit == "" or (unit.endswith("B") and unit[:-1].lower() in _BYTE_PREFIXES):
        rate = value * _BYTE_PREFIXES[unit[:-1].lower() if unit else ""]
    else:
        raise ValueError(f"invalid bandwidth unit in {text!r} (use B/s, KB/s, MB/s, KiB/s, "
                         f"MiB/s for bytes or bit/s, kbit/s, Mbit/s for bits)")
    if not math.isfinite(rate) or rate <= 0:
        raise ValueError(f"invalid bandwidth {text!r}: must be > 0")
    return rate


def _parse_loss(text: str) -> float:
    t = text.strip()
    try:
        value = float(t[:-1]) / 100.0 if t.endswith("%") else float(t)
    except ValueError:
        raise ValueError(f"invalid loss {text!r} (expected e.g. 0.01 or 1%)") from None
    if not (0.0 <= value < 1.0):
        raise ValueError(f"invalid loss {text!r}: must be in [0, 1) (or [0%, 100%))")
    return value


def _parse_hostport(text: str, lowest_port: int) -> tuple[str, int]:
    """'HOST:PORT', '[IPv6]:PORT' or 'PORT' (host 127.0.0.1)."""
    t = text.strip()
    if t.startswith("["):
        host, sep, port = t[1:].partition("]:")
    elif ":" in t:
        host, sep, port = t.rpartition(":")
    else:
        host, sep, port = "127.0.0.1", ":", t
    if not sep or not host or not port.isdigit() or not (lowest_port <= int(port) <= 65535):
        raise ValueError(f"invalid address {text!r} (expected HOST:PORT, port in "
                         f"[{lowest_port}, 65535])")
    return host, int(port)


def _arg_type(parse):
    """An argparse type from a parser raising ValueError: argparse then reports
    'argument --OPTION: <message naming the value>' and exits with status 2."""
    def convert(text):
        try:
            return parse(text)
        except ValueError as exc:
            raise argparse.ArgumentTypeError(str(exc)) from None
    convert.__name__ = parse.__name__
    return convert


def _seed_type(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid seed {text!r} (expected an integer)") from None


def _describe(s: dict) -> str:
    bw = "unlimited" if s["bandwidth"] is None else f"{s['bandwidth'] / 1e6:g} MB/s"
    return (f"delay {s['delay'] * 1e3:g} ms each way, jitter {s['jitter'] * 1e3:g} ms, "
            f"loss {s['loss'] * 100:g}%, bandwidth {bw}")


def _build_parser() -> argparse.ArgumentParser:
    presets = "; ".join(f"{name}: {_describe(p)}" for name, p in PRESETS.items())
    parser = argparse.ArgumentParser(
        prog="python -m wmo.remote.proxy",
        description="Forward TCP connections to a target, adding delay, jitter, loss and "
                    "a bandwidth cap in each direction (a user-space stand-in for netem). "
                    "Runs until Ctrl-C or SIGTERM.",
        epilog=f"Presets: {presets}. Options given with --preset override its values.")
    parser.add_argument("--target", required=True, metavar="HOST:PORT",
                        type=_arg_type(lambda t: _parse_hostport(t, 1)),
                        help="where connections are forwarded")
    parser.add_argument("--listen", default=("127.0.0.1", 0), metavar="HOST:PORT",
                        type=_arg_type(lambda t: _parse_hostport(t, 0)),
                        help="where to listen (default 127.0.0.1:0, a free port, printed)")
    parser.add_argument("--preset", choices=sorted(PRESETS), help="start from these settings")
    parser.add_argument("--delay", type=_arg_type(parse_duration), metavar="DURATION",
                        help="one-way delay added in each direction, e.g. 20ms, 0.02s, 0.02")
    parser.add_argument("--jitter", type=_arg_type(parse_duration), metavar="DURATION",
                        help="extra random delay, uniform in [0, jitter), never reordering")
    parser.add_argument("--loss", type=_arg_type(_parse_loss), metavar="P",
                        help="probability a chunk is lost and retransmitted late, e.g. "
                             "0.01 or 1%%")
    parser.add_argument("--bandwidth", type=_arg_type(parse_bandwidth), default=_UNSET,
                        metavar="RATE",
                        help="per direction and connection, e.g. 1MB/s, 8Mbit/s, 125000 "
                             "(bytes/s) or unlimited")
    parser.add_argument("--retransmit-timeout", type=_arg_type(parse_duration),
                        metavar="DURATION",
                        help="minimum extra delay of a lost chunk (default 200ms)")
    parser.add_argument("--seed", type=_seed_type, help="seed for jitter and loss")
    return parser


def main(argv: list[str] | None = None) -> int:
    """CLI: ``python -m wmo.remote.proxy --target HOST:PORT [--listen HOST:PORT]
    [--delay 20ms] [--jitter 2ms] [--loss 0.01] [--bandwidth 1MB/s] [--preset wan20]
    [--seed N]``; runs until Ctrl-C or SIGTERM and returns 0. Durations accept '20ms',
    '0.02', '0.02s'; bandwidth accepts '1MB/s', '8Mbit/s', '125000' (bytes/s). A bad
    value returns 2 after a message on stderr naming the option and the value."""
    parser = _build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit as exc:  # argparse exits: 0 for --help, 2 for a bad argument
        return exc.code if isinstance(exc.code, int) else 2

    settings = dict(PRESETS[args.preset]) if args.preset else dict(PRESETS["lan"])
    for name in ("delay", "jitter", "loss", "retransmit_timeout"):
        if getattr(args, name) is not None:
            settings[name] = getattr(args, name)
    if args.bandwidth is not _UNSET:
        settings["bandwidth"] = args.bandwidth
    try:
        proxy = LatencyProxy(*args.target, listen_host=args.listen[0],
                             listen_port=args.listen[1], seed=args.seed, **settings)
    except ValueError as exc:  # parsing catches nearly everything; this is the backstop
        parser.print_usage(sys.stderr)
        print(f"{parser.prog}: error: {exc}", file=sys.stderr)
        return 2

    logging.basicConfig(level=logging.INFO, format="%(name)s: %(message)s")
    try:
        proxy.start()
    except OSError as exc:
        print(f"{parser.prog}: error: cannot listen on {args.listen[0]}:{args.listen[1]}: "
              f"{exc}", file=sys.stderr)
        return 1

    stop = threading.Event()
    previous = {}
    if threading.current_thread() is threading.main_thread():
        for signum in (signal.SIGINT, signal.SIGTERM):
            previous[signum] = signal.signal(signum, lambda *_: stop.set())
    try:
        host, port = proxy.address
        print(f"listening on {host}:{port} -> {args.target[0]}:{args.target[1]} "
              f"({_describe(proxy.settings)})", flush=True)
        while not stop.wait(0.5):  # a timed wait keeps signal handlers responsive
            pass
    except KeyboardInterrupt:
        pass
    finally:
        proxy.stop()
        for signum, handler in previous.items():
            signal.signal(signum, handler)
    print(f"stopped; stats: {proxy.stats}", file=sys.stderr, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())

"""Network impairments for the fault suite: namespaces, nftables, a delaying relay.

Faults are made without traffic-control qdiscs (``tc ... netem``), which not every kernel
has: every car process runs in its own network namespace, joined to the root namespace by
a veth pair on a bridge (``10.77.X.1`` the root side, where mocap-sim and the observers
live; ``10.77.X.(10+N)`` car N); loss is an nftables ``numgen random`` drop on the car
namespace's input, a partition drops everything between one car and the others, a cut
link drops the car's commands on their way out; delay is a userspace relay in the path
of each Zenoh link, TCP or UDP, holding every chunk or datagram for a random time without
reordering. Everything needs root (:func:`available` says). A :class:`Lab` removes all it
made on exit; a lab whose process was killed cannot, so each records its maker in
``OWNERS`` and :func:`sweep_stale` removes the labs whose maker is gone.
"""

from __future__ import annotations

import asyncio
import contextlib
import heapq
import json
import logging
import os
import random
import secrets
import selectors
import shutil
import signal
import socket
import subprocess
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

log = logging.getLogger(__name__)

TABLE = "trustfg"
OWNERS = Path("/run/trustfg-netem")
"""One file per lab, ``<tag>.owner``: the pid and start time of the process that made it
(``/run`` is a tmpfs, cleared at boot with the namespaces in ``/run/netns``)."""


def available() -> str | None:
    """None if namespaces and nftables can be used here, else why not."""
    if os.geteuid() != 0:
        return "network namespaces and nftables need root"
    for tool in ("ip", "nft"):
        if shutil.which(tool) is None:
            return f"{tool} is not installed (tests/setup-system.sh installs it)"
    return None


def sh(*argv: str, stdin: str | None = None, check: bool = True) -> subprocess.CompletedProcess:
    done = subprocess.run(argv, input=stdin, capture_output=True, text=True)
    if check and done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)}: {done.stderr.strip() or done.returncode}")
    return done


def _remove_namespace(name: str, within_s: float = 5.0) -> bool:
    """Kill what still runs in a namespace and delete it, retrying for ``within_s``; a
    namespace that will not go is logged, never silently left (the retry guards against a
    deletion that does not take; a single unchecked ``ip netns del`` can leave one behind).
    Whether it is gone."""
    deadline = time.monotonic() + within_s
    while True:
        for pid in sh("ip", "netns", "pids", name, check=False).stdout.split():
            with contextlib.suppress(ProcessLookupError, ValueError):
                os.kill(int(pid), signal.SIGKILL)
        done = sh("ip", "netns", "del", name, check=False)
        if done.returncode == 0 or "No such file" in done.stderr:
            return True
        if time.monotonic() > deadline:
            log.error("could not remove network namespace %s: %s", name, done.stderr.strip())
            return False
        time.sleep(0.1)


def _started(pid: int) -> int | None:
    """The start time of process ``pid`` (clock ticks after boot), None if there is none:
    with the pid, it names a process even after the pid is reused."""
    try:
        stat = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    return int(stat.rsplit(")", 1)[1].split()[19])  # field 22, counted after the name


def _write_owner(tag: str) -> None:
    OWNERS.mkdir(parents=True, exist_ok=True)
    record = OWNERS / f"{tag}.owner"
    draft = record.with_suffix(".draft")
    draft.write_text(json.dumps({"pid": os.getpid(), "started": _started(os.getpid())}))
    draft.replace(record)  # atomic: a sweep never reads half a record


def _owner_alive(record: Path) -> bool:
    try:
        owner = json.loads(record.read_text())
        return _started(int(owner["pid"])) == owner["started"]
    except (OSError, ValueError, KeyError, TypeError) as exc:
        log.warning("unreadable lab owner record %s (%s): its lab counts as stale", record, exc)
        return False


def sweep_stale() -> list[str]:
    """Remove the namespaces and bridges of labs whose maker is gone (a test run killed
    before its labs' ``__exit__``); return the tags of those now gone. Labs of live
    processes, and namespaces that no record names, are left alone."""
    if not OWNERS.is_dir():
        return []
    stale = [record for record in sorted(OWNERS.glob("*.owner")) if not _owner_alive(record)]
    if not stale:
        return []
    listing = sh("ip", "netns", "list", check=False).stdout
    namespaces = [line.split()[0] for line in listing.splitlines() if line.strip()]
    swept = []
    for record in stale:
        tag = record.stem
        gone = [_remove_namespace(name) for name in namespaces if name.startswith(f"tfg{tag}c")]
        sh("ip", "link", "del", f"tfg{tag}br", check=False)
        if not all(gone):  # logged by _remove_namespace; the record stays for the next sweep
            continue
        record.unlink(missing_ok=True)
        log.warning("removed the network namespaces of lab %s, whose process is gone", tag)
        swept.append(tag)
    return swept


@dataclass
class Lab:
    car_ids: list[int]
    tag: str = field(default_factory=lambda: secrets.token_hex(2))
    subnet: int = field(default_factory=lambda: random.randint(100, 250))
    hosts: dict[int, int] | None = None
    """Car id -> the host (namespace) it runs in, several cars to a host; default: every
    car in a namespace of its own (host = car id)."""

    def __post_init__(self) -> None:
        self.bridge = f"tfg{self.tag}br"
        self.infra_ip = f"10.77.{self.subnet}.1"
        self.created: list[tuple[str, str]] = []
        self.relays: list[DelayRelay | DatagramRelay] = []

    def host(self, car_id: int) -> int:
        return (self.hosts or {}).get(car_id, car_id)

    def ns(self, car_id: int) -> str:
        return f"tfg{self.tag}c{self.host(car_id)}"

    def car_ip(self, car_id: int) -> str:
        return f"10.77.{self.subnet}.{10 + self.host(car_id)}"

    def in_host(self, host: int, argv: list[str]) -> list[str]:
        """A command line that runs ``argv`` in a host's namespace."""
        return ["ip", "netns", "exec", f"tfg{self.tag}c{host}", *argv]

    def car_ips(self) -> dict[int, str]:
        return {car: self.car_ip(car) for car in self.car_ids}

    # --- lifecycle ---------------------------------------------------------------------

    def __enter__(self) -> "Lab":
        sweep_stale()
        _write_owner(self.tag)  # before anything is made: nothing of a lab lacks an owner
        try:
            sh("ip", "link", "add", self.bridge, "type", "bridge")
            self.created.append(("link", self.bridge))
            sh("ip", "addr", "add", f"{self.infra_ip}/24", "dev", self.bridge)
            sh("ip", "link", "set", self.bridge, "up")
            for car in sorted({self.host(c): c for c in self.car_ids}.values()):  # one per namespace
                ns, host, inner = self.ns(car), f"tfg{self.tag}h{self.host(car)}", f"tfg{self.tag}i{self.host(car)}"
                sh("ip", "netns", "add", ns)
                self.created.append(("netns", ns))
                sh("ip", "link", "add", host, "type", "veth", "peer", "name", inner)
                self.created.append(("link", host))
                sh("ip", "link", "set", inner, "netns", ns)
                sh("ip", "link", "set", host, "master", self.bridge)
                sh("ip", "link", "set", host, "up")
                sh("ip", "netns", "exec", ns, "ip", "addr", "add", f"{self.car_ip(car)}/24", "dev", inner)
                sh("ip", "netns", "exec", ns, "ip", "link", "set", inner, "up")
                sh("ip", "netns", "exec", ns, "ip", "link", "set", "lo", "up")
        except Exception:
            self.__exit__(None, None, None)
            raise
        return self

    def __exit__(self, *exc) -> None:
        for relay in self.relays:
            relay.close()
        gone = True
        for kind, name in reversed(self.created):
            if kind == "netns":
                gone = _remove_namespace(name) and gone
            else:
                sh("ip", "link", "del", name, check=False)
        self.created.clear()
        if gone:  # a namespace that would not go keeps its owner record: a later sweep retries
            (OWNERS / f"{self.tag}.owner").unlink(missing_ok=True)

    def wrap(self, name: str, argv: list[str]) -> list[str]:
        """Start car processes inside their namespaces; everything else stays put."""
        if name.startswith("car "):
            return ["ip", "netns", "exec", self.ns(int(name.split()[1])), *argv]
        return argv

    # --- faults ------------------------------------------------------------------------

    def _nft(self, car: int, rules: str) -> None:
        sh("ip", "netns", "exec", self.ns(car), "nft", "-f", "-", stdin=rules)

    def clear(self, car: int) -> None:
        sh("ip", "netns", "exec", self.ns(car), "nft", "delete", "table", "inet", TABLE, check=False)

    def clear_all(self) -> None:
        """Lift every fault of every car (loss, partition, link cut)."""
        for car in self.car_ids:
            self.clear(car)

    def loss(self, car: int, percent: int) -> None:
        """Drop ``percent`` % of every packet that arrives in car's namespace."""
        self.clear(car)
        self._nft(car, f"""table inet {TABLE} {{
  chain input {{
    type filter hook input priority 0; policy accept;
    iifname "lo" accept
    numgen random mod 100 < {int(percent)} counter drop
  }}
}}""")

    def isolate_hosts(self) -> None:
        """Drop every packet between different hosts: what one host's cars say reaches
        another's only through something in the root namespace (a Zenoh router)."""
        for host in sorted({self.host(c) for c in self.car_ids}):
            car = next(c for c in self.car_ids if self.host(c) == host)
            self._drop_traffic_with(car, {self.car_ip(c) for c in self.car_ids if self.host(c) != host})

    def partition(self, car: int) -> None:
        """Cut car off from the other cars (it still sees the mocap and drives its car)."""
        self._drop_traffic_with(car, {self.car_ip(c) for c in self.car_ids if c != car})

    def _drop_traffic_with(self, car: int, addresses: set[str]) -> None:
        others = ", ".join(sorted(addresses))
        self.clear(car)
        self._nft(car, f"""table inet {TABLE} {{
  chain input {{
    type filter hook input priority 0; policy accept;
    ip saddr {{ {others} }} counter drop
  }}
  chain output {{
    type filter hook output priority 0; policy accept;
    ip daddr {{ {others} }} counter drop
  }}
}}""")

    def cut_link(self, car: int, port: int) -> None:
        """Drop car's command datagrams on their way to its car."""
        self.clear(car)
        self._nft(car, f"""table inet {TABLE} {{
  chain output {{
    type filter hook output priority 0; policy accept;
    udp dport {int(port)} counter drop
  }}
}}""")

    def relay(self, target_host: str, target_port: int, delay_s: float, jitter_s: float,
              datagrams: bool = False) -> tuple[str, int]:
        """A delaying relay (TCP, or UDP with ``datagrams``) in the root namespace in front
        of target; its address."""
        kind = DatagramRelay if datagrams else DelayRelay
        relay = kind(self.infra_ip, (target_host, target_port), delay_s, jitter_s)
        relay.start()
        self.relays.append(relay)
        return relay.address


class DelayRelay:
    """A TCP relay that holds every chunk for delay +- jitter seconds, in order."""

    def __init__(self, host: str, target: tuple[str, int], delay_s: float, jitter_s: float, seed: int = 0):
        self.host = host
        self.target = target
        self.delay_s = delay_s
        self.jitter_s = jitter_s
        self.rng = random.Random(seed)
        self.address: tuple[str, int] = (host, 0)
        self._loop: asyncio.AbstractEventLoop | None = None
        self._thread: threading.Thread | None = None
        self._ready = threading.Event()
        self._server = None
        self.chunks = 0

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="delay-relay", daemon=True)
        self._thread.start()
        if not self._ready.wait(5):
            raise RuntimeError("the delay relay did not start")

    def _run(self) -> None:
        self._loop = asyncio.new_event_loop()
        asyncio.set_event_loop(self._loop)
        self._server = self._loop.run_until_complete(asyncio.start_server(self._serve, self.host, 0))
        self.address = self._server.sockets[0].getsockname()[:2]
        self._ready.set()
        try:
            self._loop.run_forever()
        finally:
            # Cancel every connection and wait for them to finish here: a task left pending
            # would be finalised later by the garbage collector, in whatever thread runs it.
            self._server.close()
            tasks = asyncio.all_tasks(self._loop)
            for task in tasks:
                task.cancel()
            self._loop.run_until_complete(asyncio.gather(*tasks, return_exceptions=True))
            self._loop.run_until_complete(self._server.wait_closed())
            self._loop.close()

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        # Ends quietly when cancelled at close: asyncio (3.11) asks a connection's task for
        # its exception once it is done, and a cancelled one answers with a traceback.
        with contextlib.suppress(asyncio.CancelledError):
            try:
                up_reader, up_writer = await asyncio.open_connection(*self.target)
            except OSError:
                writer.close()
                return
            await asyncio.gather(self._pump(reader, up_writer), self._pump(up_reader, writer),
                                 return_exceptions=True)

    async def _pump(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        queue: asyncio.Queue = asyncio.Queue()

        async def release() -> None:
            while True:
                due, data = await queue.get()
                if data is None:
                    break
                wait = due - time.monotonic()
                if wait > 0:
                    await asyncio.sleep(wait)
                writer.write(data)
                await writer.drain()

        sender = asyncio.create_task(release())
        last_due = 0.0
        try:
            while data := await reader.read(65536):
                delay = max(0.0, self.rng.uniform(self.delay_s - self.jitter_s, self.delay_s + self.jitter_s))
                last_due = max(last_due, time.monotonic() + delay)  # never overtake the chunk before
                self.chunks += 1
                queue.put_nowait((last_due, data))
        finally:
            queue.put_nowait((0.0, None))
            with contextlib.suppress(Exception):
                await sender
            writer.close()

    def close(self) -> None:
        if self._loop is not None and self._loop.is_running():
            self._loop.call_soon_threadsafe(self._loop.stop)
        if self._thread is not None:
            self._thread.join(5)


class DatagramRelay:
    """A UDP relay that holds every datagram for delay +- jitter seconds, in order per
    direction. Each client (source address) gets its own upstream socket, so the target
    sees one peer per client, as it would without the relay."""

    def __init__(self, host: str, target: tuple[str, int], delay_s: float, jitter_s: float, seed: int = 0):
        self.target = target
        self.delay_s = delay_s
        self.jitter_s = jitter_s
        self.rng = random.Random(seed)
        self.front = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        self.front.bind((host, 0))
        self.address: tuple[str, int] = self.front.getsockname()[:2]
        self.upstream: dict[tuple, socket.socket] = {}
        """client address -> the socket that speaks for it to the target"""
        self.client_of: dict[socket.socket, tuple] = {}
        self.due: list[tuple[float, int, socket.socket, bytes, tuple | None]] = []
        """heap of (due, order, socket to send from, datagram, address or None = connected)"""
        self.last_due: dict[tuple, float] = {}
        self.datagrams = 0
        self._order = 0
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._run, name="datagram-relay", daemon=True)
        self._thread.start()

    def _hold(self, flow: tuple, send_from: socket.socket, data: bytes, to: tuple | None) -> None:
        delay = max(0.0, self.rng.uniform(self.delay_s - self.jitter_s, self.delay_s + self.jitter_s))
        due = max(self.last_due.get(flow, 0.0), time.monotonic() + delay)  # never overtake the one before
        self.last_due[flow] = due
        self._order += 1
        self.datagrams += 1
        heapq.heappush(self.due, (due, self._order, send_from, data, to))

    def _run(self) -> None:
        with selectors.DefaultSelector() as selector:
            selector.register(self.front, selectors.EVENT_READ)
            while not self._stop.is_set():
                wait = 0.05 if not self.due else min(0.05, max(0.0, self.due[0][0] - time.monotonic()))
                for key, _ in selector.select(wait):
                    sock = key.fileobj
                    try:
                        data, source = sock.recvfrom(65536)
                    except OSError:
                        continue  # e.g. ICMP unreachable from the target: the datagram is lost
                    if sock is self.front:
                        up = self.upstream.get(source)
                        if up is None:
                            up = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
                            up.connect(self.target)
                            self.upstream[source], self.client_of[up] = up, source
                            selector.register(up, selectors.EVENT_READ)
                        self._hold((source, "up"), up, data, None)
                    else:
                        client = self.client_of[sock]
                        self._hold((client, "down"), self.front, data, client)
                now = time.monotonic()
                while self.due and self.due[0][0] <= now:
                    _, _, send_from, data, to = heapq.heappop(self.due)
                    with contextlib.suppress(OSError):  # a full buffer or unreachable target: lost, as UDP is
                        send_from.sendto(data, to) if to is not None else send_from.send(data)
        for sock in [self.front, *self.upstream.values()]:
            sock.close()

    def close(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(5)
        else:
            self.front.close()  # never started: its thread did not get to close it

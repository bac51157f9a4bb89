"""Two "hosts" on one machine: two Linux network namespaces joined by a veth pair, each end with a private
address (10.231.0.1/30 and 10.231.0.2/30 by default; they exist only inside the namespaces, so two pairs at
once do not clash). Needs root and iproute2 (``ip netns``).

    with VethPair() as (a, b):
        subprocess.run([*a.prefix(), "ip", "addr"])   # runs inside namespace a; b.address is the far end

The namespaces are named ``cpgw-<pid>-<n>-a``/``-b`` after the creating process; entering a pair first
deletes the pairs of processes that are gone (a crashed run), and leaving it always deletes its own
(deleting a namespace deletes the veth end inside it, and with it the other end).

Spokes: N namespaces, each joined to the ROOT namespace by a veth pair of its own on a /30 of
10.232.0.0/16 (``Spokes``); the root end's address is the namespace's gateway, where a server of the root
namespace (listening on 0.0.0.0 or on that address) is reached:

    with Spokes(2) as spokes:
        for s in spokes:
            subprocess.run([*s.prefix(), "curl", f"http://{s.gateway}:8000/"])

The root ends' addresses are visible machine-wide, so each /30 is taken only when no root address lies in
it (allocation under a lock file: runs side by side get different ones).
"""

from __future__ import annotations

import fcntl
import ipaddress
import itertools
import os
import re
import shutil
import subprocess
import time
from collections.abc import Callable
from dataclasses import dataclass

#: Name prefix of the namespaces this module creates (how stale ones from a crashed run are recognised).
PREFIX = "cpgw"
#: The default /30 of a pair: .1 is host a, .2 host b.
DEFAULT_SUBNET = "10.231.0.0/30"
#: Where Spokes take their /30s from (.1 of each: the root end, the gateway; .2: the namespace's end).
SPOKES_BASE = "10.232.0.0/16"
#: Lock file serialising the choice and assignment of the spokes' root addresses across processes.
SPOKES_LOCK = "/tmp/cpgw-spokes.lock"

_serial = itertools.count()


@dataclass(frozen=True)
class Host:
    """One end of the pair: its namespace, veth device and address."""

    netns: str
    device: str
    address: str

    def prefix(self) -> list[str]:
        """The command prefix that runs a program inside this namespace."""
        return ["ip", "netns", "exec", self.netns]

    def link_bytes(self) -> tuple[int, int]:
        """(rx, tx) bytes counted on this end's veth device so far."""
        rx, tx = (int(_ip(["ip", "netns", "exec", self.netns, "cat",
                           f"/sys/class/net/{self.device}/statistics/{k}_bytes"]).strip())
                  for k in ("rx", "tx"))
        return rx, tx


def unavailable() -> str | None:
    """Why network namespaces cannot be made here (not root, no ``ip``), or None when they can."""
    if shutil.which("ip") is None:
        return "iproute2 ('ip') is not installed"
    if os.geteuid() != 0:
        return "creating network namespaces needs root"
    try:
        _ip(["ip", "netns", "list"])
    except (OSError, subprocess.CalledProcessError) as exc:
        return f"'ip netns' does not work here: {exc}"
    return None


def _ip(args: list[str]) -> str:
    return subprocess.run(args, check=True, capture_output=True, text=True, timeout=30).stdout


def _names() -> list[str]:
    return [line.split()[0] for line in _ip(["ip", "netns", "list"]).splitlines() if line.strip()]


def _links() -> list[str]:
    """The names of the root namespace's network devices (``cw1s0r0``, not ``cw1s0r0@if2``)."""
    return [line.split(":")[1].strip().split("@")[0]
            for line in _ip(["ip", "-o", "link", "show"]).splitlines() if line.count(":") >= 2]


def process_alive(pid: int) -> bool:
    """Whether process ``pid`` exists (also when it is another user's): how stale resources of crashed runs,
    named after their creator's pid, are recognised."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


#: A spoke's root-side veth end: ``cw<pid>s<serial>r<k>``.
_ROOT_END = re.compile(r"cw(\d+)s\d+r\d+")


def remove_stale() -> list[str]:
    """Delete the namespaces of this module whose creating process is gone, and the spokes' root-side veth
    ends of such processes still left (a namespace outlives its deletion while a process runs in it, and
    with it the veth); their names."""
    gone = []
    for name in _names():
        parts = name.split("-")
        if len(parts) == 4 and parts[0] == PREFIX and parts[1].isdigit() and not process_alive(int(parts[1])):
            subprocess.run(["ip", "netns", "delete", name], capture_output=True, timeout=30)
            gone.append(name)
    for name in _links():
        match = _ROOT_END.fullmatch(name)
        if match and not process_alive(int(match.group(1))):
            subprocess.run(["ip", "link", "delete", name], capture_output=True, timeout=30)
            gone.append(name)
    return gone


#: Wall s a new veth end may take to come up (it usually takes a few ms; a loaded machine, longer).
UP_TIMEOUT_S = 30.0


def is_up(host: Host) -> bool:
    """The veth end is operationally up (its carrier: the peer end is up too) and has its address."""
    return _end_up(["-n", host.netns], host.device, host.address)


def _end_up(where: list[str], device: str, address: str) -> bool:
    """``is_up`` of a device in the namespace ``where`` selects (``[]``: the root namespace)."""
    link = _ip(["ip", *where, "-o", "link", "show", "dev", device])
    addr = _ip(["ip", *where, "-o", "-4", "addr", "show", "dev", device])
    flags = link.split("<", 1)[1].split(">", 1)[0].split(",") if "<" in link else []
    return "LOWER_UP" in flags and " state UP " in link and f"inet {address}/" in addr \
        and "tentative" not in addr


def _wait(check: Callable[[], bool], what: str, timeout: float) -> None:
    end = time.monotonic() + timeout
    while not check():
        if time.monotonic() > end:
            raise RuntimeError(f"{what} not up within {timeout} s")
        time.sleep(0.01)


def wait_until_up(host: Host, timeout: float = UP_TIMEOUT_S) -> None:
    """Block until ``is_up(host)``. A DDS participant started in the namespace before that finds only lo:
    Fast DDS then announces 127.0.0.1 as its address, and the far side, sending there, never reaches it
    (measured: a node started right after the pair's creation was not discovered in 20 s; 1 s later, it
    was within 3 s). RuntimeError after ``timeout`` wall s."""
    _wait(lambda: is_up(host), f"{host.device} in {host.netns}", timeout)


class VethPair:
    """Context manager: two namespaces (lo up in each) joined by a veth pair with the two host addresses
    of ``subnet`` (a /30); yields the two Hosts; always deletes both namespaces on exit."""

    def __init__(self, subnet: str = DEFAULT_SUBNET):
        net = ipaddress.ip_network(subnet)
        first, second = list(net.hosts())[:2]
        serial = next(_serial)
        tag = f"{PREFIX}-{os.getpid()}-{serial}"
        dev = f"cw{os.getpid()}x{serial}"  # + a/b: at most 15 characters with a 7-digit pid
        self.hosts = (Host(f"{tag}-a", f"{dev}a", str(first)), Host(f"{tag}-b", f"{dev}b", str(second)))
        self.prefixlen = net.prefixlen

    def __enter__(self) -> tuple[Host, Host]:
        remove_stale()
        try:
            a, b = self.hosts
            for h in self.hosts:
                _ip(["ip", "netns", "add", h.netns])
            _ip(["ip", "link", "add", a.device, "netns", a.netns, "type", "veth",
                 "peer", "name", b.device, "netns", b.netns])
            for h in self.hosts:
                _ip(["ip", "-n", h.netns, "addr", "add", f"{h.address}/{self.prefixlen}", "dev", h.device])
                _ip(["ip", "-n", h.netns, "link", "set", "lo", "up"])
                _ip(["ip", "-n", h.netns, "link", "set", h.device, "multicast", "on", "up"])
            for h in self.hosts:
                wait_until_up(h)
        except BaseException:
            self.remove()
            raise
        return self.hosts

    def remove(self) -> None:
        """Delete both namespaces (and so the veth pair); ones already gone are skipped."""
        present = set(_names())
        for h in self.hosts:
            if h.netns in present:
                subprocess.run(["ip", "netns", "delete", h.netns], capture_output=True, timeout=30)

    def __exit__(self, *exc) -> None:
        self.remove()


@dataclass(frozen=True)
class Spoke(Host):
    """A namespace joined to the root namespace: its end (``device``, ``address``) and the root end
    (``root_device``, ``gateway``: where the namespace reaches a server of the root namespace)."""

    gateway: str
    root_device: str


def _root_networks() -> list[ipaddress.IPv4Network]:
    """The networks of the root namespace's IPv4 addresses."""
    return [ipaddress.ip_interface(line.split()[3]).network
            for line in _ip(["ip", "-o", "-4", "addr", "show"]).splitlines() if len(line.split()) > 3]


class Spokes:
    """Context manager: ``n`` namespaces (lo up in each), the k-th joined to the root namespace by a veth
    pair on the k-th free /30 of ``base`` (.1 root end = gateway, .2 namespace end; the default route of
    the namespace goes to the gateway); yields the n Spokes once every end is up with carrier and address;
    always deletes the pairs and namespaces on exit.

    Names: namespaces ``cpgw-<pid>-<serial>-s<k>`` (cleaned by ``remove_stale`` like VethPair's), veth ends
    ``cw<pid>s<serial>r<k>`` (root) / ``...n<k>`` (namespace); IP forwarding is not touched, so a namespace
    reaches the root namespace's own addresses only, never another namespace or the outside."""

    def __init__(self, n: int, base: str = SPOKES_BASE):
        if n < 1:
            raise ValueError(f"Spokes need n >= 1, not {n}")
        serial = next(_serial)
        tag, dev = f"{PREFIX}-{os.getpid()}-{serial}", f"cw{os.getpid()}s{serial}"
        if len(f"{dev}r{n - 1}") > 15:  # Linux interface names: at most 15 characters
            raise ValueError(f"{n} spokes: device name {dev}r{n - 1} is longer than 15 characters")
        self.n, self.base = n, ipaddress.ip_network(base)
        self._names = [(f"{tag}-s{k}", f"{dev}n{k}", f"{dev}r{k}") for k in range(n)]
        self.spokes: tuple[Spoke, ...] = ()

    def _free_subnets(self) -> list[ipaddress.IPv4Network]:
        used = _root_networks()
        free = []
        for net in self.base.subnets(new_prefix=30):
            if not any(net.overlaps(u) for u in used):
                free.append(net)
                if len(free) == self.n:
                    return free
        raise RuntimeError(f"no {self.n} free /30s left in {self.base}")

    def __enter__(self) -> tuple[Spoke, ...]:
        remove_stale()
        try:
            for ns, _, _ in self._names:
                _ip(["ip", "netns", "add", ns])
                _ip(["ip", "-n", ns, "link", "set", "lo", "up"])
            with open(SPOKES_LOCK, "a") as lock:
                fcntl.flock(lock, fcntl.LOCK_EX)
                spokes = []
                for (ns, dev, root_dev), net in zip(self._names, self._free_subnets(), strict=True):
                    gateway, address = (str(a) for a in list(net.hosts())[:2])
                    _ip(["ip", "link", "add", root_dev, "type", "veth", "peer", "name", dev, "netns", ns])
                    _ip(["ip", "addr", "add", f"{gateway}/30", "dev", root_dev])
                    spokes.append(Spoke(ns, dev, address, gateway, root_dev))
            for s in spokes:
                _ip(["ip", "link", "set", s.root_device, "multicast", "on", "up"])
                _ip(["ip", "-n", s.netns, "addr", "add", f"{s.address}/30", "dev", s.device])
                _ip(["ip", "-n", s.netns, "link", "set", s.device, "multicast", "on", "up"])
                _ip(["ip", "-n", s.netns, "route", "add", "default", "via", s.gateway])
            self.spokes = tuple(spokes)
            for s in spokes:
                wait_until_up(s)
                _wait(lambda s=s: _end_up([], s.root_device, s.gateway), s.root_device, UP_TIMEOUT_S)
        except BaseException:
            self.remove()
            raise
        return self.spokes

    @property
    def gateways(self) -> list[str]:
        """The root ends' addresses (a server meant for every spoke listens on these, or on 0.0.0.0)."""
        return [s.gateway for s in self.spokes]

    def remove(self) -> None:
        """Delete the root-side veth ends (each takes its peer along at once, where deleting a namespace
        frees its devices a little later) and the namespaces; ones already gone are skipped."""
        links = set(_links())
        for _, _, root_dev in self._names:
            if root_dev in links:
                subprocess.run(["ip", "link", "delete", root_dev], capture_output=True, timeout=30)
        present = set(_names())
        for ns, _, _ in self._names:
            if ns in present:
                subprocess.run(["ip", "netns", "delete", ns], capture_output=True, timeout=30)

    def __exit__(self, *exc) -> None:
        self.remove()

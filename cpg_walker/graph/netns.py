"""Two "hosts" on one machine: two Linux network namespaces joined by a veth pair, each end with a private
address (10.231.0.1/30 and 10.231.0.2/30 by default; they exist only inside the namespaces, so two pairs at
once do not clash). Needs root and iproute2 (``ip netns``).

    with VethPair() as (a, b):
        subprocess.run([*a.prefix(), "ip", "addr"])   # runs inside namespace a; b.address is the far end

The namespaces are named ``cpgw-<pid>-<n>-a``/``-b`` after the creating process; entering a pair first
deletes the pairs of processes that are gone (a crashed run), and leaving it always deletes its own
(deleting a namespace deletes the veth end inside it, and with it the other end).
"""

from __future__ import annotations

import ipaddress
import itertools
import os
import shutil
import subprocess
from dataclasses import dataclass

#: Name prefix of the namespaces this module creates (how stale ones from a crashed run are recognised).
PREFIX = "cpgw"
#: The default /30 of a pair: .1 is host a, .2 host b.
DEFAULT_SUBNET = "10.231.0.0/30"

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


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def remove_stale() -> list[str]:
    """Delete the namespaces of this module whose creating process is gone; their names."""
    gone = []
    for name in _names():
        parts = name.split("-")
        if len(parts) == 4 and parts[0] == PREFIX and parts[1].isdigit() and not _alive(int(parts[1])):
            subprocess.run(["ip", "netns", "delete", name], capture_output=True, timeout=30)
            gone.append(name)
    return gone


#: Wall s a new veth end may take to come up (it usually takes a few ms; a loaded machine, longer).
UP_TIMEOUT_S = 30.0


def is_up(host: Host) -> bool:
    """The veth end is operationally up (its carrier: the peer end is up too) and has its address."""
    link = _ip(["ip", "-n", host.netns, "-o", "link", "show", "dev", host.device])
    addr = _ip(["ip", "-n", host.netns, "-o", "-4", "addr", "show", "dev", host.device])
    flags = link.split("<", 1)[1].split(">", 1)[0].split(",") if "<" in link else []
    return "LOWER_UP" in flags and " state UP " in link and f"inet {host.address}/" in addr \
        and "tentative" not in addr


def wait_until_up(host: Host, timeout: float = UP_TIMEOUT_S) -> None:
    """Block until ``is_up(host)``. A DDS participant started in the namespace before that finds only lo:
    Fast DDS then announces 127.0.0.1 as its address, and the far side, sending there, never reaches it
    (measured: a node started right after the pair's creation was not discovered in 20 s; 1 s later, it
    was within 3 s). RuntimeError after ``timeout`` wall s."""
    import time

    end = time.monotonic() + timeout
    while not is_up(host):
        if time.monotonic() > end:
            raise RuntimeError(f"{host.device} in {host.netns} not up within {timeout} s")
        time.sleep(0.01)


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

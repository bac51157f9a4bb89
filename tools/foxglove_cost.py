"""The Foxglove bridge's cost: lockstep walks (cpg-walker walk's code) without it (``none``), with it and no
client (``foxidle``), with it and a WebSocket client subscribed to every channel (``fox``); prints the
real-time factor, the distance and steps (the same in all: the bridge only listens), the messages the client
got and each node's CPU seconds.

    PYTHONPATH=$PWD python tools/foxglove_cost.py 20 none foxidle fox     # 20 sim s each, in that order
"""

from __future__ import annotations

import json
import socket
import sys
import tempfile
import threading
import time

from cpg_walker.experiments.walk_graph import run_graph_walk
from cpg_walker.nodes.foxglove_view import SUBPROTOCOL


class ClientWatcher:
    """A Foxglove client (started with the graph) that subscribes to every channel and counts messages."""

    def __init__(self, port: int) -> None:
        self.port, self.counts, self.stopping = port, {}, threading.Event()

    def start(self, domain_id: int) -> None:
        threading.Thread(target=self.run, daemon=True).start()

    def stop(self) -> None:
        self.stopping.set()

    def run(self) -> None:
        from websockets.sync.client import connect

        while not self.stopping.is_set():
            try:
                ws = connect(f"ws://127.0.0.1:{self.port}", subprotocols=[SUBPROTOCOL], max_size=None)
                break
            except OSError:
                time.sleep(0.2)
        else:
            return
        topics: dict[int, str] = {}
        with ws:
            while not self.stopping.is_set():
                try:
                    raw = ws.recv(timeout=0.5)
                except TimeoutError:
                    continue
                except Exception:
                    return
                if isinstance(raw, str):
                    op = json.loads(raw)
                    if op["op"] == "advertise":
                        topics.update({c["id"]: c["topic"] for c in op["channels"]})
                        ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                            {"id": c["id"], "channelId": c["id"]} for c in op["channels"]]}))
                elif raw[0] == 1:
                    topic = topics[int.from_bytes(raw[1:5], "little")]
                    self.counts[topic] = self.counts.get(topic, 0) + 1


def free_port() -> int:
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    port = s.getsockname()[1]
    s.close()
    return port


def main(duration: float, modes: list[str]) -> None:
    out = tempfile.mkdtemp(prefix="foxglove_cost_")
    print("runs in", out)
    for i, mode in enumerate(modes):
        kw: dict = {}
        watcher = None
        if mode in ("fox", "foxidle"):
            port = free_port()
            watcher = ClientWatcher(port) if mode == "fox" else None
            kw = {"foxglove": f"127.0.0.1:{port}", "watchers": [watcher] if watcher else []}
        r = run_graph_walk(f"{out}/run{i}_{mode}", duration=duration, **kw)
        print(json.dumps({"mode": mode, "rtf": r["real_time_factor"], "distance_m": r["distance_m"],
                          "steps": r["steps"], "wall_s": r["graph"]["wall_s_total"],
                          "cpu_s": r["graph"]["cpu_s"],
                          "client_msgs": watcher.counts if watcher else None}), flush=True)


if __name__ == "__main__":
    main(float(sys.argv[1]), sys.argv[2:])

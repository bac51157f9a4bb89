"""A node process stopped by SIGINT exits cleanly wherever the signal lands: here inside a garbage
collector callback (the CI failure of stop 25: ``Exception ignored in GcPauses._callback ...
KeyboardInterrupt``, a traceback in pid_node's log at the end of a fault test)."""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

from cpg_walker.graph.processes import isolated_env

pytestmark = pytest.mark.ros

NODE = textwrap.dedent("""
    import gc, os, signal, sys, time

    import rclpy

    from cpg_walker.nodes.runtime import run_main

    def loop(node):
        sent = []

        def signal_mid_collection(phase, info):  # the signal arrives while a collection is being timed
            if phase == "start" and not sent:
                sent.append(1)
                os.kill(os.getpid(), signal.SIGINT)
                t = time.perf_counter()
                while time.perf_counter() - t < 0.05:  # Python code runs on: the handler fires here
                    pass

        gc.callbacks.insert(0, signal_mid_collection)
        give_up = time.monotonic() + 20.0
        while rclpy.ok() and time.monotonic() < give_up:
            gc.collect()
            time.sleep(0.01)
        print("context", "ok" if rclpy.ok() else "shut down", "sent", len(sent), file=sys.stderr, flush=True)

    sys.exit(run_main(["probe"], lambda: rclpy.create_node("probe"), loop=loop))
""")


def test_sigint_inside_a_gc_callback_exits_without_a_traceback(ros_domain):
    out = subprocess.run([sys.executable, "-c", NODE], env=isolated_env(ros_domain), capture_output=True,
                         text=True, timeout=60)
    assert "context shut down sent 1" in out.stderr, out.stderr
    assert "Traceback" not in out.stderr and "KeyboardInterrupt" not in out.stderr, out.stderr
    assert out.returncode == 0, out.stderr

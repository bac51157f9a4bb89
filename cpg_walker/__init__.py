"""cpg_walker: programmable central pattern generators driving a simulated HOAP-2 through ROS 2.

Layers, bottom up (each imports only those below it; test/test_layers.py names every allowed edge):
``cpg`` the generic CPG (oscillators, networks, teaching); ``robot`` the MuJoCo HOAP-2, PID law, contact;
``walker`` the HOAP-2 CPG controller (learning, storage, start-up, feedback, the in-process loop);
``nodes`` the rclpy nodes and their support; ``graph`` the tools that run and inspect the node graph
(processes, ros2cli stand-ins, network namespaces); ``experiments`` the paper's figures, sweeps and
benchmarks; ``cli`` the ``cpg-walker`` command. ``paths`` and ``progress`` are shared utilities.
"""

__version__ = "0.1.0"

"""cpg_walker: programmable central pattern generators driving a simulated HOAP-2 through ROS 2.

Pure algorithms live in `cpg` (oscillators, networks, feedback) and `robot` (MuJoCo model, PID law,
gait data); `nodes` wraps them in rclpy; `cli` is the `cpg-walker` command; `experiments` reproduces
the paper's figures and runs sweeps and benchmarks.
"""

__version__ = "0.1.0"

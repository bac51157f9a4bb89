"""ament_python package cpg_walker (also installable with pip: `pip install -e .`)."""

from glob import glob

from setuptools import find_packages, setup

PACKAGE = "cpg_walker"

# Every node and tool installed as a console script: `ros2 run cpg_walker <name>` finds them in
# lib/cpg_walker (see setup.cfg); a pip install puts them on the venv's bin/.
NODES: dict[str, str] = {
    "sim_node": "cpg_walker.nodes.sim_node:main",
    "pid_node": "cpg_walker.nodes.pid_node:main",
    "target_player_node": "cpg_walker.nodes.target_player_node:main",
    "cpg_node": "cpg_walker.nodes.cpg_node:main",
    "recorder_node": "cpg_walker.nodes.recorder_node:main",
    "foxglove_node": "cpg_walker.nodes.foxglove_node:main",
    "relay_node": "cpg_walker.nodes.relay_node:main",
    "odom_node": "cpg_walker.nodes.odom_node:main",
}
TOOLS = {
    "cpg-walker": "cpg_walker.cli.main:main",
}

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test"]),
    package_data={PACKAGE: ["robot/*.xml", "robot/*.urdf", "robot/data/*.csv", "robot/data/*.md"]},
    data_files=[
        ("share/ament_index/resource_index/packages", [f"resource/{PACKAGE}"]),
        (f"share/{PACKAGE}", ["package.xml"]),
        (f"share/{PACKAGE}/config", glob("config/*.yaml")),
        (f"share/{PACKAGE}/launch", glob("launch/*.py")),
        # the URDF generated from the MJCF (one file: the package's copy, also beside the MJCF)
        (f"share/{PACKAGE}/urdf", [f"{PACKAGE}/robot/hoap2.urdf"]),
        (f"share/{PACKAGE}/rviz", glob("rviz/*.rviz")),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="cpg_walker developers",
    maintainer_email="cpg-walker@example.org",
    description="Programmable CPGs learned from the HOAP-2 walk, driving a MuJoCo HOAP-2 through ROS 2.",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [f"{name}={target}" for name, target in {**NODES, **TOOLS}.items()],
    },
)

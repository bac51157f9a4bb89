"""The package as a ROS user and a new developer meet it: manifest, set-up, colcon install tree, purity."""

from __future__ import annotations

import ast
import os
import subprocess
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent


def test_package_xml_is_format_3_with_ros_dependencies() -> None:
    root = ET.parse(REPO / "package.xml").getroot()
    assert root.get("format") == "3"
    assert root.findtext("name") == "cpg_walker"
    assert root.find("export/build_type").text == "ament_python"
    exec_deps = {e.text for e in root.findall("exec_depend")}
    for dep in ("rclpy", "sensor_msgs", "std_msgs", "geometry_msgs", "nav_msgs", "rosgraph_msgs",
                "rcl_interfaces", "diagnostic_msgs", "python3-numpy"):
        assert dep in exec_deps, dep
    test_deps = {e.text for e in root.findall("test_depend")}
    assert {"python3-pytest", "ament_flake8", "ament_pep257", "ament_copyright"} <= test_deps


def test_setup_cfg_installs_scripts_where_ros2_run_looks() -> None:
    text = (REPO / "setup.cfg").read_text()
    assert "script_dir=$base/lib/cpg_walker" in text
    assert "install_scripts=$base/lib/cpg_walker" in text


@pytest.mark.slow
def test_colcon_build_produces_a_ros2_run_install_tree() -> None:
    result = subprocess.run([sys.executable, str(REPO / "tools" / "colcon_check.py")],
                            capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stdout + result.stderr
    assert "ros2 run cpg_walker cpg-walker" in result.stdout


def test_setup_without_python312_says_what_to_do(tmp_path: Path) -> None:
    env = {"PATH": "/usr/bin:/bin", "HOME": str(tmp_path)}  # no pyenv, no python3.12 on this PATH
    if any(Path(d, "python3.12").exists() for d in ("/usr/bin", "/bin")):
        pytest.skip("this machine has a system python3.12; the no-interpreter path cannot be exercised")
    result = subprocess.run(["bash", str(REPO / "tools" / "find_python312.sh")],
                            env=env, capture_output=True, text=True)
    assert result.returncode == 1
    assert "no Python 3.12 interpreter found" in result.stderr
    assert "pyenv install 3.12" in result.stderr


def test_setup_finds_a_real_python312() -> None:
    result = subprocess.run(["bash", str(REPO / "tools" / "find_python312.sh")],
                            capture_output=True, text=True, env=dict(os.environ))
    assert result.returncode == 0, result.stderr
    version = subprocess.run([result.stdout.strip(), "-c", "import sys; print(sys.version_info[:2])"],
                             capture_output=True, text=True).stdout.strip()
    assert version == "(3, 12)"


@pytest.mark.parametrize("subpackage", ["cpg", "robot"])
def test_pure_core_never_imports_rclpy(subpackage: str) -> None:
    for path in (REPO / "cpg_walker" / subpackage).rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            names = []
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module]
            assert not any(n.split(".")[0] in ("rclpy", "launch", "launch_ros") for n in names), path


def test_cli_lists_its_commands() -> None:
    from cpg_walker.cli.main import build_parser

    help_text = build_parser().format_help()
    for command in ("demo", "bench"):
        assert command in help_text

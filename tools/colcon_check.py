"""Build cpg_walker with colcon the way a ROS 2 workspace would, and check the install tree has what
`ros2 run cpg_walker <exe>` and `ros2 launch` look up. Usage: python tools/colcon_check.py [--keep DIR]

Checks: the ament index marker (share/ament_index/resource_index/packages/cpg_walker), package.xml,
config/, launch/, urdf/hoap2.urdf (the same text as the package's) and rviz/ under share/cpg_walker, an
executable lib/cpg_walker/<name> for every console script in setup.py, the MJCF, URDF and gait data
inside the installed Python package, and that `ros2 run`'s own lookup
(ament_index_python.get_package_prefix + lib/<pkg>/<exe>) resolves each executable and that it starts.
Exit status 0 when all hold; otherwise it names what is missing.
"""

from __future__ import annotations

import argparse
import ast
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
PKG = "cpg_walker"


def console_scripts() -> list[str]:
    """Names of the console scripts declared in setup.py (read from its NODES and TOOLS dicts)."""
    tree = ast.parse((REPO / "setup.py").read_text())
    names: list[str] = []
    for node in ast.walk(tree):
        if isinstance(node, ast.AnnAssign | ast.Assign) and isinstance(node.value, ast.Dict):
            targets = [node.target] if isinstance(node, ast.AnnAssign) else node.targets
            if any(isinstance(t, ast.Name) and t.id in ("NODES", "TOOLS") for t in targets):
                names += [k.value for k in node.value.keys if isinstance(k, ast.Constant)]
    return names


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--keep", help="build in this directory and keep it (default: a temporary one)")
    args = parser.parse_args()
    work = Path(args.keep) if args.keep else Path(tempfile.mkdtemp(prefix="colcon_check_"))
    (work / "src").mkdir(parents=True, exist_ok=True)
    # Copy the tracked sources (not .venv, results, build dirs), as a fresh clone would have them.
    files = subprocess.run(
        ["git", "ls-files", "--cached", "--others", "--exclude-standard"],
        cwd=REPO, check=True, capture_output=True, text=True,
    ).stdout.split()
    dest = work / "src" / PKG
    for rel in files:
        if (REPO / rel).is_file():
            (dest / rel).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / rel, dest / rel)
    colcon = Path(sys.executable).with_name("colcon")
    print(f"colcon_check: building in {work}")
    build = subprocess.run(
        [str(colcon), "build", "--base-paths", "src", "--event-handlers", "console_direct-"],
        cwd=work, capture_output=True, text=True,
    )
    if build.returncode != 0:
        print(build.stdout[-4000:], build.stderr[-4000:], sep="\n")
        print("colcon_check: FAILED: colcon build exited", build.returncode)
        return 1
    prefix = work / "install" / PKG
    py_site = prefix / "lib" / f"python{sys.version_info.major}.{sys.version_info.minor}" / "site-packages"
    problems: list[str] = []
    expect = [
        prefix / "share" / "ament_index" / "resource_index" / "packages" / PKG,
        prefix / "share" / PKG / "package.xml",
        py_site / PKG / "robot",
    ]
    expect += [prefix / "share" / PKG / "config" / p.name for p in sorted((REPO / "config").glob("*.yaml"))]
    expect += [prefix / "share" / PKG / "launch" / p.name for p in sorted((REPO / "launch").glob("*.py"))]
    expect += [py_site / PKG / "robot" / p.name for p in sorted((REPO / PKG / "robot").glob("*.xml"))]
    # the URDF (generated from the MJCF: in the Python package for sim_node, in share/ for the launch file
    # and robot_state_publisher) and the RViz view
    expect += [py_site / PKG / "robot" / "hoap2.urdf", prefix / "share" / PKG / "urdf" / "hoap2.urdf"]
    expect += [prefix / "share" / PKG / "rviz" / p.name for p in sorted((REPO / "rviz").glob("*.rviz"))]
    expect += [py_site / PKG / "robot" / "data" / p.name
               for p in sorted((REPO / PKG / "robot" / "data").glob("*"))]
    problems += [f"missing {p.relative_to(work)}" for p in expect if not p.exists()]
    urdfs = [prefix / "share" / PKG / "urdf" / "hoap2.urdf", py_site / PKG / "robot" / "hoap2.urdf"]
    if all(p.exists() for p in urdfs) and urdfs[0].read_bytes() != urdfs[1].read_bytes():
        problems.append("share/cpg_walker/urdf/hoap2.urdf differs from the Python package's hoap2.urdf")

    env = dict(os.environ)
    env["AMENT_PREFIX_PATH"] = f"{prefix}:{env.get('AMENT_PREFIX_PATH', '')}".rstrip(":")
    env["PYTHONPATH"] = f"{py_site}:{env.get('PYTHONPATH', '')}".rstrip(":")
    exes = console_scripts()
    for exe in exes:
        # ros2run's lookup: package prefix from the ament index, then lib/<package>/<executable>.
        lookup = subprocess.run(
            [sys.executable, "-c",
             "import os, sys; from ament_index_python.packages import get_package_prefix; "
             f"p = os.path.join(get_package_prefix('{PKG}'), 'lib', '{PKG}', '{exe}'); "
             "print(p); sys.exit(0 if os.access(p, os.X_OK) else 1)"],
            env=env, capture_output=True, text=True,
        )
        if lookup.returncode != 0:
            problems.append(f"ros2 run lookup failed for {exe}: {lookup.stdout.strip()} "
                            f"{lookup.stderr.strip()}")
            continue
        path = lookup.stdout.strip()
        started = subprocess.run([path, "--help"], env=env, capture_output=True, text=True, timeout=60)
        if started.returncode != 0:
            problems.append(f"{path} --help exited {started.returncode}: {started.stderr.strip()[-500:]}")
        else:
            print(f"colcon_check: ok  ros2 run {PKG} {exe} -> {path}")
    for p in problems:
        print("colcon_check: FAILED:", p)
    if not problems:
        print(f"colcon_check: ok  {len(expect)} install files, {len(exes)} executables")
    if not args.keep:
        shutil.rmtree(work, ignore_errors=True)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())

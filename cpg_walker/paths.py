"""Where the package's shared files (config/, launch/) are, for every way it can be installed."""

from __future__ import annotations

import sys
from pathlib import Path

from cpg_walker.errors import InputError

PACKAGE = "cpg_walker"
_REPO_ROOT = Path(__file__).resolve().parent.parent


def share_dir() -> Path:
    """The package's share directory: the source tree (editable/pip -e), a colcon/ament install
    (`<prefix>/share/cpg_walker`), or a plain pip install into `sys.prefix/share/cpg_walker`."""
    if (_REPO_ROOT / "package.xml").is_file() and (_REPO_ROOT / "config").is_dir():
        return _REPO_ROOT
    try:
        from ament_index_python.packages import get_package_share_directory

        return Path(get_package_share_directory(PACKAGE))
    except Exception:  # ament index absent or package not registered: fall through
        pass
    candidate = Path(sys.prefix) / "share" / PACKAGE
    if candidate.is_dir():
        return candidate
    raise FileNotFoundError(
        f"cannot find the {PACKAGE} share directory (config/, launch/): not a source checkout, "
        "not in the ament index, not under sys.prefix/share"
    )


def config_path(name: str) -> Path:
    """Path of `config/<name>`; raises FileNotFoundError naming the file if it is absent."""
    path = share_dir() / "config" / name
    if not path.is_file():
        raise FileNotFoundError(f"config file not found: {path}")
    return path


def yaml_error(path: str | Path, exc: Exception) -> str:
    """One line for a YAML file the parser refused: the file, the line and column where it stopped (when
    the parser gives them) and its reason, e.g. ``cpg.yaml:3:5: not valid YAML: expected ',' or ']'``."""
    mark = getattr(exc, "problem_mark", None) or getattr(exc, "context_mark", None)
    where = f"{path}:{mark.line + 1}:{mark.column + 1}" if mark is not None else str(path)
    problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
    return f"{where}: not valid YAML: {problem}"


def ros_parameters(file: str | Path, node: str) -> dict:
    """The ``ros__parameters`` of ``node`` in a ROS 2 parameters file (a bare name: in config/; else a
    path),
    flattened the way ROS does: nested keys joined with '.' (``kp: {leg: 100.0}`` -> ``kp.leg``).

    This is the same file the node gets with ``--ros-args --params-file``; the in-process code reads it
    here so that both use one value. A missing file, node section or ``ros__parameters`` is a ValueError
    (FileNotFoundError for the file) naming the file."""
    import yaml

    path = Path(file)
    if len(path.parts) == 1 and not path.is_absolute():
        path = config_path(str(file))
    with open(path, encoding="utf-8") as fh:
        try:
            doc = yaml.safe_load(fh)
        except yaml.YAMLError as exc:
            raise InputError(yaml_error(path, exc)) from None
    section = doc.get(node) if isinstance(doc, dict) else None
    params = section.get("ros__parameters") if isinstance(section, dict) else None
    if not isinstance(params, dict):
        raise InputError(f"{path}: expected '{node}: ros__parameters: {{...}}' (a ROS 2 parameters file)")
    flat: dict = {}

    def walk(prefix: str, value: object) -> None:
        if isinstance(value, dict):
            for key, sub in value.items():
                walk(f"{prefix}.{key}" if prefix else str(key), sub)
        else:
            flat[prefix] = value

    walk("", params)
    return flat

"""Where the package's shared files (config/, launch/) are, for every way it can be installed."""

from __future__ import annotations

import sys
from pathlib import Path

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

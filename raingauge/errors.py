"""Exceptions raised by raingauge.

Every error a user can cause derives from :class:`RaingaugeError`; its message
names the problem and the fix.  The command line prints it without a traceback
and exits with status 2.
"""


class RaingaugeError(Exception):
    """Base class of all user-facing errors."""


class ProfileError(RaingaugeError, ValueError):
    """A camera profile (TOML) is missing, malformed or physically impossible."""


class ConfigError(RaingaugeError, ValueError):
    """An instrument configuration file or option is missing or malformed."""


class InputError(RaingaugeError, ValueError):
    """An input file (video, image folder, data file) is unreadable or unsuitable."""


class SourceError(RaingaugeError, RuntimeError):
    """A frame source (camera, stream) failed or vanished."""

"""The installed distribution's version, from package metadata."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("gearjax")
except PackageNotFoundError:  # a source tree on sys.path, not installed
    __version__ = "0+unknown"

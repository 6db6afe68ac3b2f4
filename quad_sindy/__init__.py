"""The ``quad-sindy`` command line, on top of quad_envs, identification and agents."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("quad-sindy")
except PackageNotFoundError:  # running from a source tree that was not installed
    __version__ = "0+unknown"

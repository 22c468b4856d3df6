"""The version of shspec, written once: setuptools reads it from here for the package metadata."""

__version__ = "0.1.0"

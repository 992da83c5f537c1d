"""Exceptions raised for bad input; the CLI prints them as one clear line and exits with status 2."""

from __future__ import annotations


class GrutrackError(Exception):
    """Base class of every error grutrack raises for bad input or configuration."""


class InputFormatError(GrutrackError, ValueError):
    """An input file does not have the expected format: the message names the file, field and expectation."""


class ConfigError(GrutrackError, ValueError):
    """A configuration file or value is invalid: the message names the file and key."""


class DatasetError(GrutrackError, FileNotFoundError):
    """A dataset root, version or split cannot be found or read."""


class OutputPathError(GrutrackError, OSError):
    """An output path cannot be written: it is a folder, or its folder cannot be created or written."""

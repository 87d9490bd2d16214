"""The package version, in one place below every layer (files record it as provenance)."""

__version__ = "0.1.0"

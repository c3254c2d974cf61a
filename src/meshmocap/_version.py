"""The package version, in a base module of its own so that modules below the package root
read it without importing ``meshmocap`` (whose ``__getattr__`` reaches the API above them)."""

__version__ = "0.1.0"

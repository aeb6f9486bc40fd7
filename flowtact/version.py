"""The version of flowtact, in a module of its own so that modules stamping it on recordings and
provenance need not import the package's top level (which imports them back)."""

__version__ = "0.1.0"

"""Suites of the signal family."""

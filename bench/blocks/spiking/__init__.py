"""Suites of the spiking family."""

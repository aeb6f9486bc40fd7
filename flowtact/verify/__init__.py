"""Checking blocks: what the conformance suite expected and got, and numerical stress cases."""
